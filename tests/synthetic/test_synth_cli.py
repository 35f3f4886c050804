"""``setdiff-bench synth``: the tiny preset end to end (scene + fit), reruns keep finished work."""

from __future__ import annotations

import json

from setdiff_bench.cli.main import main
from setdiff_bench.gaussians.ply import read_ply


def test_synth_tiny_generates_and_fits(tmp_path, capsys):
    code = main(["synth", "--out", str(tmp_path), "--preset", "tiny", "--seed", "11", "--jobs", "1", "--no-progress"])
    assert code == 0
    scene = tmp_path / "scene_0011_00"
    meta = json.loads((scene / "scene.json").read_text())
    assert meta["preset"] == "tiny" and meta["seed"] == 11
    model = read_ply(scene / "fits" / "lane0.ply")
    assert len(model) > 0
    assert not (scene / "fits" / "lane0.checkpoint").exists()
    before = (scene / "fits" / "lane0.ply").stat().st_mtime_ns
    capsys.readouterr()
    assert main(["synth", "--out", str(tmp_path), "--preset", "tiny", "--seed", "11", "--jobs", "1",
                 "--no-progress"]) == 0
    assert "fit already present" in capsys.readouterr().out
    assert (scene / "fits" / "lane0.ply").stat().st_mtime_ns == before
    # the same folder with another preset is refused with one line
    code = main(["synth", "--out", str(tmp_path), "--preset", "default", "--seed", "11", "--scenes", "1",
                 "--no-fit", "--jobs", "1", "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--overwrite" in err
