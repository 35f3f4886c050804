"""``setdiff-bench render``: files per view, values equal to an in-memory render, resume, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.images import read_exr, read_image_raw
from setdiff_bench.loaders.colmap import read_colmap_model
from tests.gaussians.render_fixtures import render_args, write_inputs


def test_render_verb_writes_views_and_resumes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_inputs(tmp_path, 200)
    args = render_args(tmp_path)
    assert main(args) == 0
    for view in ("view_1", "view_2"):
        for name in ("rgb.png", "cmap.exr", "depth.exr", "alpha.png"):
            assert (tmp_path / "out" / view / name).is_file()
    camera = read_colmap_model(tmp_path / "sparse").cameras["view_2.jpg"]
    expected = render(read_ply(tmp_path / "scene.ply"), camera)
    cmap = read_exr(tmp_path / "out" / "view_2" / "cmap.exr", channels=3)
    assert np.allclose(cmap, expected.cmap[0].permute(1, 2, 0).numpy(), atol=1e-6)
    rgb = read_image_raw(tmp_path / "out" / "view_2" / "rgb.png", "uint8")
    assert np.array_equal(
        rgb, np.rint(expected.rgb[0].clamp(0, 1).permute(1, 2, 0).numpy() * 255).astype(np.uint8)
    )
    stamp = (tmp_path / "out" / "view_1" / "rgb.png").stat().st_mtime_ns
    assert main(args) == 0
    assert (tmp_path / "out" / "view_1" / "rgb.png").stat().st_mtime_ns == stamp
    assert "0 view(s)" in capsys.readouterr().out.splitlines()[-1].replace("rendered ", "")


def test_render_verb_bad_input_is_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_inputs(tmp_path, 10)
    code = main(render_args(tmp_path, "--images", "nope.jpg"))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "nope.jpg" in err[0] and "sparse" in err[0]
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())
    (tmp_path / "broken.ply").write_bytes(b"ply\nformat ascii 1.0\n")
    code = main(render_args(tmp_path, ply="broken.ply", out="out2"))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "broken.ply" in err[0]


def test_distorted_camera_is_rendered_as_its_pinhole_and_said_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Regression: a SIMPLE_RADIAL camera was rendered as a pinhole image without a word."""
    write_inputs(tmp_path, 200, radial=0.08)
    assert main(render_args(tmp_path, "--downscale", "2")) == 0
    assert "2 of 2 camera(s) have lens distortion" in capsys.readouterr().err
    rgb = read_image_raw(tmp_path / "out" / "view_1" / "rgb.png", "uint8")
    assert rgb.shape[:2] == (15, 20)  # --downscale 2 of 40x30
