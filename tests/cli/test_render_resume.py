"""Issue 45, defect 1: ``render`` resumes only the work it started (same PLY, COLMAP model and settings).

A second ``render`` into a finished folder with another PLY, another COLMAP model or another
``--downscale`` used to report "0 view(s), N already complete" and keep the first images; now it is
refused in one line (exit 2) and the folder is left as it was.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.gaussians.ply import write_ply
from tests.gaussians.gaussian_fixtures import random_scene
from tests.gaussians.render_fixtures import render_args, write_inputs, write_model


def _snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def rendered(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    """``tmp_path/out`` rendered from ``scene.ply`` and ``sparse`` (two 40x30 views)."""
    write_inputs(tmp_path, 60)
    assert main(render_args(tmp_path, "--device", "cpu", "--no-progress")) == 0
    capsys.readouterr()
    return tmp_path


def _refused(tmp_path: Path, argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    before = _snapshot(tmp_path / "out")
    assert main([*argv, "--device", "cpu", "--no-progress"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert _snapshot(tmp_path / "out") == before
    return lines[0]


def test_same_inputs_resume(rendered: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(render_args(rendered, "--device", "cpu", "--no-progress")) == 0
    assert "rendered 0 view(s), 2 already complete" in capsys.readouterr().out


def test_another_ply_is_refused(rendered: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_ply(rendered / "other.ply", random_scene(60, seed=2))
    line = _refused(rendered, render_args(rendered, ply="other.ply"), capsys)
    record = rendered / "out" / "render.json"
    assert line == (
        f"setdiff-bench render: error: {record}: these renders were made with another --ply (SHA-256 "
        "differs); render into another --out, or delete the old renders first"
    )
    # the other PLY renders into a fresh folder, so the refusal protected different images
    assert main([*render_args(rendered, ply="other.ply", out="fresh"), "--no-progress"]) == 0
    old, new = (rendered / name / "view_1" / "rgb.png" for name in ("out", "fresh"))
    assert old.read_bytes() != new.read_bytes()


def test_another_downscale_is_refused(rendered: Path, capsys: pytest.CaptureFixture[str]) -> None:
    line = _refused(rendered, render_args(rendered, "--downscale", "2"), capsys)
    assert line.endswith(
        "made with --downscale 1 (now 2); render into another --out, or delete the old renders first"
    )


def test_another_colmap_model_is_refused(rendered: Path, capsys: pytest.CaptureFixture[str]) -> None:
    shutil.rmtree(rendered / "sparse")
    write_model(rendered / "sparse", radial=0.01)  # the same image names, another camera
    assert "another --colmap model" in _refused(rendered, render_args(rendered), capsys)


def test_unrecorded_views_are_refused(rendered: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (rendered / "out" / "render.json").unlink()
    line = _refused(rendered, render_args(rendered), capsys)
    assert "holds 2 rendered view(s) but no render.json" in line
