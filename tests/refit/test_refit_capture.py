"""``refit`` on a capture read through a dataset loader that needs an option: an instant-ngp style
``transforms.json`` listing a frame without its photo (as NVlabs/instant-ngp's fox does) is refused with one
line that names the option, and refitted once ``--loader-option missing=skip`` is given."""

from __future__ import annotations

import json

import pytest

from setdiff_bench.cli.main import main
from tests.gaussians.fit.capture_fixtures import write_capture


@pytest.mark.filterwarnings("ignore::UserWarning")
def test_refit_takes_loader_options(tmp_path, capsys) -> None:
    capture = tmp_path / "root"
    write_capture(capture / "capture")
    out = tmp_path / "refit"
    args = [
        "refit",
        "nerfstudio",
        "--root",
        str(capture),
        "--scene",
        "capture",
        "--group",
        "holdout8",
        "--fit-iterations",
        "2",
        "--method",
        "identity",
        "--schedule",
        "one-shot",
        "--steps",
        "2",
        "--min-fit-correlation",
        "-1",
        "--device",
        "cpu",
        "--no-progress",
        "--out",
        str(out),
    ]
    assert main(args) == 2  # the absent photo is refused by default, in one line naming the refit's flag
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "transforms.json" in err and "--loader-option missing=skip" in err
    assert not out.exists()
    assert main([*args, "--loader-option", "missing=skip"]) == 0
    manifest = json.loads((out / "capture" / "holdout8.refit.json").read_text())
    # holdout8 of the 3 frames with a photo: the first is the target, the other two are fitted on
    assert manifest["targets"] == 1 and manifest["identity"]["loader_options"] == {"missing": "skip"}
    assert (out / "capture" / "holdout8.ply").is_file()
    assert main([*args, "--loader-option", "missing"]) == 2  # a malformed option names the refit's flag
    assert "--loader-option" in capsys.readouterr().err
