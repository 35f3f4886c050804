"""``render --trajectory`` (issue 41): novel views equal an in-memory render at the moved cameras; bad
trajectories are one line, exit 2, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.images import read_exr
from setdiff_bench.loaders.colmap import read_colmap_model
from setdiff_bench.packets.trajectory import shifted
from tests.gaussians.render_fixtures import render_args, write_inputs


def test_shifted_trajectory_renders_the_moved_cameras(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_inputs(tmp_path, 200)
    assert main(render_args(tmp_path, "--trajectory", "shift:0.5", "--no-progress")) == 0
    assert "of trajectory shift+0.5m (no ground truth)" in capsys.readouterr().out
    folders = sorted(p.name for p in (tmp_path / "out").iterdir() if p.is_dir())
    assert folders == ["view_1@shift+0.5m", "view_2@shift+0.5m"]
    camera = read_colmap_model(tmp_path / "sparse").cameras["view_2.jpg"]
    moved = shifted(camera, 0.5)
    assert np.allclose(moved.center - camera.center, 0.5 * camera.R[0])
    expected = render(read_ply(tmp_path / "scene.ply"), moved)
    cmap = read_exr(tmp_path / "out" / "view_2@shift+0.5m" / "cmap.exr", channels=3)
    assert np.allclose(cmap, expected.cmap[0].permute(1, 2, 0).numpy(), atol=1e-6)
    record = json.loads((tmp_path / "out" / "render.json").read_text())
    assert record["trajectory"] == "shift+0.5m"
    # another trajectory into the same folder is refused (the record says what the views are)
    assert main(render_args(tmp_path, "--trajectory", "yaw:5", "--no-progress")) == 2
    assert "--trajectory shift+0.5m" in capsys.readouterr().err


def _refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], spec: str) -> str:
    code = main(render_args(tmp_path, "--trajectory", spec, "--no-progress", out="bad"))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not (tmp_path / "bad").exists()
    return err[0]


def test_bad_trajectories_are_one_line_and_nothing_is_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_inputs(tmp_path, 200)
    line = _refused(tmp_path, capsys, "shift:50")
    assert line.startswith("setdiff-bench render: error: shift:50: 2 of 2 cameras leave the scene bounds")
    rotation = np.eye(4)
    rotation[0, 0] = 1.5  # a scaled axis: not a rigid pose
    poses = tmp_path / "poses.json"
    poses.write_text(json.dumps([{"name": "p", "c2w": rotation.tolist()}]))
    assert "(pose 0): rotation is not orthonormal" in _refused(tmp_path, capsys, str(poses))
    poses.write_text('[{"name": "p", "c2w": [[NaN, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}]')
    assert "NaN" in _refused(tmp_path, capsys, str(poses))
    assert "unknown trajectory 'lane:3'" in _refused(tmp_path, capsys, "lane:3")
