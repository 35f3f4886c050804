"""``setdiff-bench synth``: the tiny preset end to end (scene + fit), reruns keep finished work."""

from __future__ import annotations

import json

from setdiff_bench.cli.main import main
from setdiff_bench.gaussians.ply import read_ply


def test_synth_tiny_generates_and_fits(tmp_path, capsys):
    code = main(
        ["synth", "--out", str(tmp_path), "--preset", "tiny", "--seed", "11", "--jobs", "1", "--no-progress"]
    )
    assert code == 0
    scene = tmp_path / "scene_0011_00"
    meta = json.loads((scene / "scene.json").read_text())
    assert meta["preset"] == "tiny" and meta["seed"] == 11
    model = read_ply(scene / "fits" / "lane0.ply")
    assert len(model) > 0
    assert not (scene / "fits" / "lane0.checkpoint").exists()
    before = (scene / "fits" / "lane0.ply").stat().st_mtime_ns
    capsys.readouterr()
    assert (
        main(
            [
                "synth",
                "--out",
                str(tmp_path),
                "--preset",
                "tiny",
                "--seed",
                "11",
                "--jobs",
                "1",
                "--no-progress",
            ]
        )
        == 0
    )
    assert "fit already present" in capsys.readouterr().out
    assert (scene / "fits" / "lane0.ply").stat().st_mtime_ns == before
    # the same folder with another preset is refused with one line
    code = main(
        [
            "synth",
            "--out",
            str(tmp_path),
            "--preset",
            "default",
            "--seed",
            "11",
            "--scenes",
            "1",
            "--no-fit",
            "--jobs",
            "1",
            "--no-progress",
        ]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--overwrite" in err


def test_synth_indices_make_the_same_scene_as_the_full_list(tmp_path, capsys):
    """``--indices 1`` makes exactly the scene ``--scenes 2`` makes at index 1 (scene i depends on (seed, i) only)."""
    common = ["--preset", "tiny", "--seed", "5", "--no-fit", "--jobs", "1", "--no-progress"]
    assert main(["synth", "--out", str(tmp_path / "all"), "--scenes", "2", *common]) == 0
    assert main(["synth", "--out", str(tmp_path / "one"), "--indices", "1", *common]) == 0
    assert sorted(p.name for p in (tmp_path / "one").iterdir()) == ["scene_0005_01"]
    alone, among = tmp_path / "one" / "scene_0005_01", tmp_path / "all" / "scene_0005_01"
    files = sorted(p.relative_to(alone) for p in alone.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(among) for p in among.rglob("*") if p.is_file()) and len(files) > 10
    assert all((alone / f).read_bytes() == (among / f).read_bytes() for f in files)
    capsys.readouterr()
    for bad in ("1,x", "-1"):
        assert main(["synth", "--out", str(tmp_path / "bad"), "--indices", bad, *common]) == 2
        assert "--indices" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()
