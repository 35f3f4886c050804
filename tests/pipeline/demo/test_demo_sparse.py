"""``setdiff-bench demo --benchmark sparse``: the sparse-view benchmark's presets, test scenes and report."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.errors import UsageError
from setdiff_bench.pipeline.demo import DemoPaths, evaluation_scene_indices, report_markdown
from setdiff_bench.pipeline.presets import DEMO_BENCHMARKS, get_demo_preset

#: The sparse protocol's listed test scenes (protocols/splits/dl3dv_sparse_synthetic_test.txt), read by eye.
LISTED_TEST_SCENES = ["sparse_0000_00", "sparse_0000_01"]


def test_the_sparse_benchmark_tests_on_the_listed_scenes() -> None:
    for name in ("tiny", "default", "full"):
        assert evaluation_scene_indices(get_demo_preset(name, "sparse"), 0) == [0, 1]
    listed = Path(__file__).resolve().parents[3] / "protocols" / "splits" / "dl3dv_sparse_synthetic_test.txt"
    assert listed.read_text(encoding="utf-8").split() == LISTED_TEST_SCENES


def test_a_seed_without_listed_test_scenes_is_refused() -> None:
    with pytest.raises(UsageError, match="no test scene among seed 3's scenes") as error:
        evaluation_scene_indices(get_demo_preset("default", "sparse"), 3)
    assert error.value.one_line().startswith("--seed: ")


def test_presets_share_names_across_benchmarks() -> None:
    driving, sparse = (DEMO_BENCHMARKS[name].presets for name in ("driving", "sparse"))
    assert list(driving) == list(sparse) == ["tiny", "default", "full"]
    assert {p.benchmark for p in driving.values()} == {"driving"}
    assert {p.benchmark for p in sparse.values()} == {"sparse"}
    assert [p.synth_preset for p in sparse.values()] == ["sparse_tiny", "sparse", "sparse_large"]


def test_unknown_benchmark_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        main(["demo", "--benchmark", "waymo", "--out", str(tmp_path / "d")])
    assert exit_.value.code == 2 and "invalid choice: 'waymo'" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_report_names_the_benchmark_and_its_verdict_group(tmp_path: Path) -> None:
    board = "| Method | 3 views PSNR↑ |\n|---|---:|\n| identity | 19.84 |"
    (tmp_path / "dl3dv.md").write_text(board, encoding="utf-8")
    means = {"psnr": 20.0, "ssim": 0.7, "lpips": 0.3}
    summary = {
        "invocation": "setdiff-bench demo --benchmark sparse",
        "preset": {"name": "default", "description": "d", "benchmark": "sparse"},
        "total_seconds": 60.0,
        "stages": [],
        "outputs": ["dl3dv.md"],
        "views_3": {
            "group": "n3",
            "targets": 196,
            "means": {"identity": means, "setdiff": {**means, "psnr": 21.0}},
            "setdiff_beats_identity": {"psnr": True, "ssim": False, "lpips": False},
        },
    }
    text = report_markdown(summary, DemoPaths(out=tmp_path, work=tmp_path / "work"))
    assert text.startswith("# Sparse-view synthetic benchmark")
    assert board in text and "## At 3 views (196 targets)" in text
    assert "real DL3DV captures" in text  # the paper's rows are not like for like
    assert "SetDiff beats `identity` at 3 views: PSNR yes, SSIM no, LPIPS no." in text


def test_shipped_sparse_models_never_saw_a_sparse_test_walk() -> None:
    from setdiff_bench.pipeline.demo import check_unseen
    from setdiff_bench.synthetic.sparse import sparse_scene_name

    shipped = DEMO_BENCHMARKS["sparse"].shipped
    manifests = check_unseen([(0, 0), (0, 1)], shipped, sparse_scene_name)
    assert set(manifests) == {"setdiff", "difix"}
    for manifest in manifests.values():
        assert manifest["data"]["datasets"] == ["dl3dv"]
        assert not set(LISTED_TEST_SCENES) & set(manifest["data"]["scenes"])
    # a walk they trained on is refused, by name: the driving scene of the same (seed, index) is not
    with pytest.raises(UsageError, match="was trained on scene sparse_0000_02"):
        check_unseen([(0, 2)], shipped, sparse_scene_name)
    assert set(
        check_unseen([(0, 2)], DEMO_BENCHMARKS["sparse"].shipped, lambda s, i: f"scene_{s:04d}_{i:02d}")
    )


def tree_digest(folder: Path) -> dict[str, str]:
    """``{relative path: SHA-256}`` of every file under ``folder``."""
    return {
        str(path.relative_to(folder)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(folder.rglob("*"))
        if path.is_file()
    }


def test_sparse_demo_after_the_driving_demo_in_readme_order(
    shipped_demo_out: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The README's two demos in its order with default folders: ``demo --preset tiny`` (the session's shipped
    tiny demo, in ``runs/demo``), then ``demo --benchmark sparse --preset tiny`` from the same folder.  The sparse
    demo writes to ``runs/demo_sparse`` (the two listed test walks at 64x40, their n3/n6/n9 fits, DL3DV packets,
    the four methods with the shipped sparse models, Table 4's layout beside the paper's rows) and leaves every
    byte of the driving demo as it was; pointed at the driving folder, it refuses before any work."""
    import json

    import pandas as pd

    folder = shipped_demo_out.parents[1]
    before = tree_digest(shipped_demo_out)
    previous = Path.cwd()
    try:
        os.chdir(folder)
        capsys.readouterr()
        refused = main(
            ["demo", "--benchmark", "sparse", "--preset", "tiny", "--out", "runs/demo", "--no-progress"]
        )
        refusal = capsys.readouterr().err.strip().splitlines()
        assert main(["demo", "--benchmark", "sparse", "--preset", "tiny", "--no-progress"]) == 0
        printed = capsys.readouterr().out
    finally:
        os.chdir(previous)
    assert refused == 2 and len(refusal) == 1
    assert "holds the driving demo's outputs" in refusal[0] and "runs/demo_sparse" in refusal[0]
    assert tree_digest(shipped_demo_out) == before
    out = folder / "runs" / "demo_sparse"
    summary = json.loads((out / "demo.json").read_text(encoding="utf-8"))
    assert summary["test_scenes"] == LISTED_TEST_SCENES
    assert {m["shipped"] for m in summary["models"].values()} == {"tiny_setdiff_sparse", "tiny_difix_sparse"}
    assert summary["views_3"]["group"] == "n3" and summary["views_3"]["targets"] > 0
    assert {"dl3dv.md", "dl3dv.parquet", "dl3dv.tex", "dl3dv_view_count.png", "dl3dv_grid.png"} <= set(
        summary["outputs"]
    )
    board = pd.read_parquet(out / "dl3dv.parquet")
    measured = board[board["source"] != "reported"]
    assert set(measured["method"]) == {"identity", "reproject", "difix", "setdiff"}
    assert (board["source"] == "reported").any()  # the paper's Table 4 rows beside ours
    text = (out / "README.md").read_text(encoding="utf-8")
    assert text.startswith("# Sparse-view synthetic benchmark") and "## At 3 views" in text
    commands = [stage["command"] for stage in summary["stages"]]
    assert any("prepare dl3dv --protocol dl3dv_sparse_synthetic" in c for c in commands)
    assert any("--checkpoint tiny_setdiff_sparse" in c for c in commands)
    # the demo ends by printing its leaderboard and whether it reproduces the published one
    assert (out / "dl3dv.md").read_text(encoding="utf-8").strip() in printed
    assert "reproduction: not compared with the published table (results/synthetic_sparse)" in printed
    assert "--preset default --seed 0" in printed
