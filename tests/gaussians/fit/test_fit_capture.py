"""``fit`` on a generic capture read through a dataset loader: an instant-ngp style ``transforms.json``
with lens distortion, a frame without its image and ``--downscale``."""

from __future__ import annotations

import numpy as np
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.gaussians.fit import load_fit_scene, load_fit_views
from setdiff_bench.gaussians.ply import read_ply
from tests.gaussians.fit.capture_fixtures import HEIGHT, WIDTH, write_capture


@pytest.fixture
def capture(tmp_path):
    """A root holding ``capture/`` (:func:`write_capture`)."""
    write_capture(tmp_path / "capture")
    return tmp_path


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_views_are_undistorted_and_downscaled(capture):
    scene = load_fit_scene(capture, dataset="nerfstudio", scene="capture", options={"missing": "skip"})
    assert len(scene.frames) == 3 and scene.frames[0].camera.distortion is not None
    [view] = load_fit_views(scene, [scene.frames[0].name], downscale=2)
    assert view.camera.distortion is None  # drawn as the pinhole it now is
    assert (view.camera.width, view.camera.height) == (WIDTH // 2, HEIGHT // 2)
    assert view.image.shape == (3, HEIGHT // 2, WIDTH // 2)
    assert np.allclose(view.camera.K[:2, :3], [[30.0, 0.0, 16.0], [0.0, 30.0, 12.0]])
    # barrel distortion leaves the corners uncovered: they are out of the loss
    assert view.mask is not None and not view.mask[0, 0, 0] and view.mask[0, HEIGHT // 4, WIDTH // 4]


def test_fit_cli_reads_a_dataset_with_loader_options(capture, tmp_path, capsys):
    out = tmp_path / "fit.ply"
    args = [
        "fit",
        "--dataset",
        "nerfstudio",
        "--root",
        str(capture),
        "--scene",
        "capture",
        "--out",
        str(out),
        "--downscale",
        "2",
        "--preset",
        "tiny",
        "--iterations",
        "2",
        "--device",
        "cpu",
        "--no-progress",
        "--init",
        "random",
    ]
    assert main(args) == 2  # the absent image is refused by default ...
    assert "-o missing=skip" in capsys.readouterr().err
    assert not out.exists()
    assert main([*args, "-o", "missing=skip"]) == 0  # ... and skipped on request, said in one stderr line
    warned = [line for line in capsys.readouterr().err.splitlines() if "1 of 4 frames" in line]
    assert len(warned) == 1 and warned[0].startswith("setdiff-bench fit: warning: "), warned
    model = read_ply(out)
    assert 1000 <= len(model) <= 1000 + 500  # sized random init (≥ 1000) + the tiny preset's 500 background
