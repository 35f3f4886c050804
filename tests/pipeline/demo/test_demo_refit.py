"""``setdiff-bench demo --refit``: the stages it declares (every enhancer refitted per test scene and group, its
refit scenes and snapshots scored as X-3D, X-3D+ and X-3D-NNNNNN, the paired comparisons), its verdict and report,
and its refusals.  The whole tiny run end to end is the slow test at the end; each stage's verb has its own tests
(tests/refit, tests/evaluation/run, tests/reporting)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.errors import UsageError
from setdiff_bench.pipeline.demo import DemoPaths, evaluation_scene_indices
from setdiff_bench.pipeline.demo._demo import check_folder
from setdiff_bench.pipeline.demo._report import refit_section
from setdiff_bench.pipeline.demo._scenes import scene_namer
from setdiff_bench.pipeline.demo._stages import DemoPlan, demo_stages
from setdiff_bench.pipeline.demo._summary import interval_winners, refit_verdict
from setdiff_bench.pipeline.presets import DEMO_BENCHMARKS, get_demo_preset


def plan(benchmark: str, tmp_path: Path) -> DemoPlan:
    preset = get_demo_preset("default", benchmark)
    return DemoPlan(
        preset,
        DEMO_BENCHMARKS[benchmark],
        DemoPaths(tmp_path / "out", tmp_path / "out" / "work"),
        tmp_path,
        0,
        2,
        None,
        False,
        False,
        evaluation_scene_indices(preset, 0),
        scene_namer(preset),
        steps={},
        configs={"setdiff": "tiny_setdiff", "difix": "tiny_difix"},
        refit=True,
    )


def flags(argv: list[object], flag: str) -> list[str]:
    return [str(argv[i + 1]) for i, part in enumerate(argv) if part == flag]


def test_driving_refits_every_enhancer_on_each_test_scene_and_scores_three_rows(tmp_path: Path) -> None:
    stages = demo_stages(plan("driving", tmp_path))
    prepare = next(s.argv for s in stages.setup if s.name == "prepare")
    assert flags(prepare, "--group") == ["lane+2", "interp"]  # the store holds the scored groups only
    assert all(flags(s.argv, "--warp") == ["on"] for s in stages.runs)
    # 4 enhancers x the 2 test scenes x lane+2, snapshots every 100 steps, the shipped models
    refits = [s for own in stages.refits.values() for s in own if s.name.startswith("refit ")]
    scoring = [s for own in stages.refits.values() for s in own if not s.name.startswith("refit ")]
    assert len(refits) == 8
    # each enhancer's refits come before the stages that score them
    assert all(
        own[0].name.startswith("refit ") and own[2].name.startswith("prepare ")
        for own in stages.refits.values()
    )
    setdiff = [s.argv for s in stages.refits["setdiff"] if s.name.startswith("refit ")]
    assert [flags(a, "--scene") for a in setdiff] == [["scene_0000_02"], ["scene_0000_04"]]
    assert all(
        flags(a, "--checkpoint") == ["tiny_setdiff"] and flags(a, "--snapshot-every") == ["100"]
        for a in setdiff
    )
    assert all(flags(a, "--out") == ["out/work/refit/setdiff"] for a in setdiff)
    # only the test scenes exist: each refit and prepare declares them, so all share the packets' split
    assert all(flags(a, "--test-scene") == ["scene_0000_02", "scene_0000_04"] for a in setdiff)
    assert flags(prepare, "--test-scene") == ["scene_0000_02", "scene_0000_04"]
    runs = {s.name: s.argv for s in scoring if s.name.startswith("run ")}
    assert sorted(runs) == sorted(
        f"run {m}-3D{suffix}"
        for m in ("identity", "reproject", "difix", "setdiff")
        for suffix in ("", "-000100", "-000200", *(["+"] if m != "identity" else []))
    )
    assert flags(runs["run setdiff-3D+"], "--method") == ["setdiff"]
    assert flags(runs["run setdiff-3D"], "--method") == ["identity"]
    assert flags(runs["run setdiff-3D-000100"], "--refit") == ["out/work/refit/setdiff/snapshots/step-000100"]
    assert flags(runs["run setdiff-3D+"], "--refit") == ["out/work/refit/setdiff"]
    assert "--cost" in stages.leaderboard.argv
    assert flags(stages.leaderboard.argv, "--methods")[0].split(",")[:5] == [
        "identity",
        "identity-3D",
        "identity-3D-000100",
        "identity-3D-000200",
        "reproject",
    ]
    assert [s.name for s in stages.compares][:5] == [
        "compare identity-3D identity",
        "compare reproject-3D identity-3D",
        "compare reproject-3D+ reproject",
        "compare reproject-3D reproject",
        "compare reproject-3D+ reproject-3D",
    ]


def test_sparse_refits_each_view_counts_fit_without_warp(tmp_path: Path) -> None:
    stages = demo_stages(plan("sparse", tmp_path))
    refit_work = [s for own in stages.refits.values() for s in own]
    refits = [s for s in refit_work if s.name.startswith("refit ")]
    assert len(refits) == 4 * 2 * 3  # enhancers x walks x (n3, n6, n9)
    assert {flags(s.argv, "--group")[0] for s in refits} == {"n3", "n6", "n9"}
    assert not any("--warp" in s.argv for s in [*stages.runs, *refit_work])
    assert all(flags(s.argv, "--protocol") == ["dl3dv_sparse_synthetic"] for s in refits)
    assert not any("--test-scene" in s.argv for s in [*stages.setup, *refit_work])


def comparison(a: str, b: str, group: str, gains: dict[str, tuple[float, bool]]) -> pd.DataFrame:
    """Group-level rows of a ``compare a b`` table: ``{metric: (gain, interval excludes 0)}``."""
    return pd.DataFrame(
        {
            "a": a,
            "b": b,
            "level": "group",
            "key": group,
            "metric": list(gains),
            "gain": [g for g, _ in gains.values()],
            "holds": [h for _, h in gains.values()],
        }
    )


def test_interval_winners_are_the_rows_no_interval_beats() -> None:
    names = ["setdiff", "setdiff-3D", "setdiff-3D+"]
    comparisons = pd.concat(
        [
            # 3D+ beats X and 3D on PSNR; on SSIM only 3D > X holds (3D+ and 3D not separated)
            comparison("setdiff-3D+", "setdiff", "n3", {"psnr": (0.5, True), "ssim": (0.01, False)}),
            comparison("setdiff-3D", "setdiff", "n3", {"psnr": (-0.2, True), "ssim": (0.02, True)}),
            comparison("setdiff-3D+", "setdiff-3D", "n3", {"psnr": (0.7, True), "ssim": (-0.01, False)}),
            # another group's rows and pairs outside the three do not count
            comparison("setdiff", "setdiff-3D+", "n6", {"psnr": (1.0, True)}),
            comparison("setdiff-3D", "identity-3D", "n3", {"psnr": (-3.0, True)}),
        ]
    )
    assert interval_winners(comparisons, "n3", names, "psnr") == ["setdiff-3D+"]
    assert interval_winners(comparisons, "n3", names, "ssim") == ["setdiff-3D", "setdiff-3D+"]
    # on n6 only X vs X 3D+ was compared: X 3D, never compared, is not shown to lose either
    assert interval_winners(comparisons, "n6", names, "psnr") == ["setdiff", "setdiff-3D"]
    assert interval_winners(comparisons, "n3", names, "lpips") == names  # no comparison: nothing shown


def test_refit_verdict_and_report(tmp_path: Path) -> None:
    def rows(name: str, psnr: float, lpips: float) -> pd.DataFrame:
        return pd.DataFrame(
            {"method": name, "group": ["lane+2"] * 2, "psnr": psnr, "ssim": 0.5, "lpips": lpips}
        )

    metrics = pd.concat(
        [
            rows("identity", 17.0, 0.30),
            rows("identity-3D", 17.1, 0.28),
            rows("setdiff", 19.0, 0.20),
            rows("setdiff-3D", 18.5, 0.25),
            rows("setdiff-3D+", 19.5, 0.15),
            pd.DataFrame(
                {"method": ["setdiff"], "group": ["interp"], "psnr": 50.0, "ssim": 0.9, "lpips": 0.0}
            ),
        ]
    )
    comparisons = pd.concat(
        [
            comparison("setdiff-3D+", "setdiff", "lane+2", {"psnr": (0.5, False), "lpips": (0.05, True)}),
            comparison("setdiff-3D", "setdiff", "lane+2", {"psnr": (-0.5, False), "lpips": (-0.05, True)}),
            comparison("setdiff-3D+", "setdiff-3D", "lane+2", {"psnr": (1.0, True), "lpips": (0.1, True)}),
        ]
    )
    verdict = refit_verdict(metrics, "lane+2", comparisons)
    assert verdict["targets"] == 2 and verdict["means"]["setdiff"]["psnr"] == 19.0  # interp left out
    assert verdict["best"]["setdiff"] == {"psnr": "setdiff-3D+", "ssim": "setdiff", "lpips": "setdiff-3D+"}
    assert verdict["best"]["identity"]["lpips"] == "identity-3D"
    assert verdict["winners"]["setdiff"] == {
        "psnr": ["setdiff", "setdiff-3D+"],  # 3D+ - X does not hold
        "ssim": ["setdiff", "setdiff-3D", "setdiff-3D+"],
        "lpips": ["setdiff-3D+"],
    }
    assert refit_verdict(metrics, "lane+2")["winners"] == {}  # no comparisons: no winners said
    refit = {"groups": [verdict], "warp": {"setdiff": 800.0, "setdiff-3D": 700.0}}
    section = "\n".join(refit_section({"refit": refit}, DemoPaths(tmp_path, tmp_path / "work"), "synthetic"))
    assert "### lane+2 (2 targets)" in section
    assert "| setdiff-3D | 18.50 | 0.500 | 0.250 | 700.0 |" in section
    assert "| setdiff-3D+ | 19.50 | 0.500 | 0.150 | – |" in section
    assert (
        "- `setdiff`: best mean PSNR `setdiff-3D+`, SSIM `setdiff`, LPIPS `setdiff-3D+`; paired intervals: "
        "PSNR `setdiff`, `setdiff-3D+`; SSIM `setdiff`, `setdiff-3D`, `setdiff-3D+`; LPIPS `setdiff-3D+`."
    ) in section
    assert refit_section({}, DemoPaths(tmp_path, tmp_path / "work"), "synthetic") == []
    (tmp_path / "synthetic_refit_steps.png").write_bytes(b"")  # the plot is linked, warp named only if scored
    for scored, said in ((refit["warp"], "Metrics and warp error against"), ({}, "- Metrics against")):
        summary = {"refit": {**refit, "warp": scored}}
        assert said in "\n".join(refit_section(summary, DemoPaths(tmp_path, tmp_path / "work"), "synthetic"))


def test_refit_demo_refuses_train_and_another_demos_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["demo", "--preset", "tiny", "--refit", "--train", "--out", str(tmp_path / "d")]) == 2
    assert "--refit scores the shipped models" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
    paths = DemoPaths(tmp_path / "plain", tmp_path / "plain" / "work")
    paths.work.mkdir(parents=True)
    (paths.work / "benchmark").write_text("driving\n")
    with pytest.raises(
        UsageError, match="holds the driving demo's outputs; pass --out for the driving\\+refit demo"
    ):
        check_folder(paths, DEMO_BENCHMARKS["driving"], refit=True)
    check_folder(paths, DEMO_BENCHMARKS["driving"])  # the plain demo may resume there


@pytest.mark.slow
def test_tiny_refit_demo_end_to_end(tmp_path: Path) -> None:
    out = tmp_path / "refit"
    assert main(["demo", "--preset", "tiny", "--refit", "--out", str(out), "--no-progress"]) == 0
    board = pd.read_parquet(out / "synthetic.parquet")
    assert (out / "synthetic_refit_steps.png").is_file() and len(list(out.glob("compare_*.md"))) == 13
    readme = (out / "README.md").read_text()
    assert "### lane+2 (" in readme and "paired intervals:" in readme and "setdiff-3D+" in readme
    rows = set(board["method"])
    assert {"identity", "identity-3D", "setdiff", "setdiff-3D", "setdiff-3D+", "difix-3D-000100"} <= rows
    assert len(rows) == 19  # 4 enhancers x (X, X-3D, 2 snapshots) + 3 X-3D+
