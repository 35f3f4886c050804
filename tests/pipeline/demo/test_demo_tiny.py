"""CI smoke test: ``setdiff-bench demo --preset tiny`` runs end to end with the shipped models and with ``--train``,
writes well-formed, shareable outputs, and gives byte-identical results when run again."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.evaluation.run import TIMING_COLUMNS
from setdiff_bench.io.images import read_image_raw
from setdiff_bench.io.run_layout import (
    ENHANCER_FILE,
    FRAGMENTS_DIR,
    KEY_COLUMNS,
    MANIFEST_FILE,
    METRICS_FILE,
    RUN_FILE,
)
from setdiff_bench.pipeline.demo import METHODS, SUMMARY_FILE
from setdiff_bench.pipeline.stages import LEDGER_FILE
from setdiff_bench.runtime.threads import compute_threads
from tests.pipeline.demo.conftest import run_tiny_demo


@pytest.fixture(scope="module")
def demo_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The whole path: scenes, training, evaluation."""
    return run_tiny_demo(tmp_path_factory.mktemp("demo"), "1", "--train")


@pytest.fixture(scope="module")
def second_demo_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return run_tiny_demo(tmp_path_factory.mktemp("demo_again"), "2", "--train")


#: Files that record wall times or absolute paths, never results (compared without those fields below).
TIMED_OR_LOCAL = {
    SUMMARY_FILE,
    "README.md",
    LEDGER_FILE,
    "train_log.jsonl",
    RUN_FILE,
    MANIFEST_FILE,
    ENHANCER_FILE,
    ".index.lock",
}


# Slow: a second --train demo.  Each stage's determinism has a faster test: fits across instruction sets and
# threads (tests/gaussians/fit/test_portable_fit.py), packets and runs killed and resumed byte-identical
# (tests/reliability/test_crash_resume.py), training resumed exactly (tests/models/test_train.py), and the
# documented numbers recomputed from their commands (tests/cli/test_documented_numbers.py).
@pytest.mark.slow
def test_same_command_gives_byte_identical_results(demo_out: Path, second_demo_out: Path) -> None:
    """Scenes, fits, packets, checkpoints, enhanced images and leaderboards are byte-identical between two
    runs of the same command (another OMP_NUM_THREADS, another moment's load); per-target metrics equal
    except their timing column."""
    files = sorted(p.relative_to(demo_out) for p in demo_out.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(second_demo_out) for p in second_demo_out.rglob("*") if p.is_file())
    compared = 0
    for relative in files:
        first, second = demo_out / relative, second_demo_out / relative
        if relative.name in TIMED_OR_LOCAL:
            continue
        if relative.name == METRICS_FILE or FRAGMENTS_DIR in relative.parts:
            a, b = (
                pd.read_parquet(first).drop(columns=list(TIMING_COLUMNS)),
                pd.read_parquet(second).drop(columns=list(TIMING_COLUMNS)),
            )
            pd.testing.assert_frame_equal(a, b, check_exact=True)
        else:
            assert first.read_bytes() == second.read_bytes(), relative
        compared += 1
    groups = {p.parts[0] if p.parts[0] != "work" else "/".join(p.parts[:2]) for p in files}
    assert {
        "work/scenes",
        "work/packets",
        "work/checkpoints",
        "work/runs",
        "synthetic.md",
        "synthetic.parquet",
        "synthetic_grid.png",
        "synthetic_lane_shift.png",
    } <= groups
    assert compared > 300
    summaries = [json.loads((out / SUMMARY_FILE).read_text()) for out in (demo_out, second_demo_out)]
    assert (
        summaries[0]["provenance"]["torch_threads"]
        == summaries[1]["provenance"]["torch_threads"]
        == compute_threads()
    )
    assert summaries[0]["files"] == summaries[1]["files"] | {"README.md": summaries[0]["files"]["README.md"]}


def test_outputs_are_shareable_under_umask_022(demo_out: Path) -> None:
    for path in [demo_out, *demo_out.rglob("*")]:
        mode = stat.S_IMODE(path.stat().st_mode)
        assert mode == (0o755 if path.is_dir() else 0o644), (path, oct(mode))


def test_demo_writes_leaderboard_with_every_method_and_group(demo_out: Path) -> None:
    board = pd.read_parquet(demo_out / "synthetic.parquet")
    assert {"dataset", "method", "block", "metric", "value", "count", "best", "source"} <= set(board.columns)
    assert set(board["method"]) == set(METHODS) and set(board["source"]) == {"measured"}
    assert {"lane+1", "lane+2", "side", "turn"} <= set(board["block"])
    assert set(board["metric"]) == {"psnr", "ssim", "lpips"}
    assert board["value"].notna().all() and (board["count"] > 0).all()
    # exactly the best value per block and metric is flagged (ties may share it)
    for (_, metric), cell in board.groupby(["block", "metric"]):
        best = cell["value"].max() if metric != "lpips" else cell["value"].min()
        flagged = cell[cell["best"]]["value"]
        assert (
            len(flagged) >= 1
            and (flagged.round(cell["decimals"].iloc[0]) == round(best, int(cell["decimals"].iloc[0]))).all()
        )
    markdown = (demo_out / "synthetic.md").read_text()
    latex = (demo_out / "synthetic.tex").read_text()
    for method in METHODS:
        assert method in markdown and method in latex
    assert "\\toprule" in latex and "\\bottomrule" in latex


def test_demo_summary_records_commands_and_verdict(demo_out: Path) -> None:
    summary = json.loads((demo_out / SUMMARY_FILE).read_text())
    names = [stage["name"] for stage in summary["stages"]]
    assert names[:2] == ["synth", "prepare"]
    assert {"train setdiff", "train difix", "leaderboard"} <= set(names)
    assert all(stage["command"].startswith("setdiff-bench ") for stage in summary["stages"])
    verdict = summary["lane_plus_2"]
    assert verdict["group"] == "lane+2" and verdict["targets"] > 0
    assert set(verdict["means"]) == set(METHODS)
    for method in METHODS:
        assert set(verdict["means"][method]) == {"psnr", "ssim", "lpips"}
    assert set(verdict["setdiff_beats_identity"]) == {"psnr", "ssim", "lpips"}
    readme = (demo_out / "README.md").read_text()
    assert summary["invocation"] in readme and "## Commands, in order" in readme


def test_demo_per_target_metrics_and_images(demo_out: Path) -> None:
    runs = demo_out / "work" / "runs"
    counts = set()
    for method in METHODS:
        frame = pd.read_parquet(runs / method / METRICS_FILE)
        assert {*KEY_COLUMNS, "psnr", "ssim", "lpips"} <= set(frame.columns)
        assert (frame["split"] == "test").all() and (frame["method"] == method).all()
        assert frame[["psnr", "ssim", "lpips"]].notna().all().all()
        counts.add(len(frame))
    assert len(counts) == 1  # every method scored the same targets
    grid = read_image_raw(demo_out / "synthetic_grid.png", "uint8")
    assert grid.ndim == 3 and grid.shape[2] >= 3 and grid.shape[0] > 48
    assert (demo_out / "synthetic_lane_shift.png").is_file()


def test_shipped_demo_evaluates_the_packaged_models_on_test_scenes_only(shipped_demo_out: Path) -> None:
    summary = json.loads((shipped_demo_out / SUMMARY_FILE).read_text())
    names = [stage["name"] for stage in summary["stages"]]
    assert names == ["synth", "prepare", *(f"run {m}" for m in METHODS), "leaderboard"]
    commands = {stage["name"]: stage["command"] for stage in summary["stages"]}
    assert "--indices 2" in commands["synth"] and "--test-scene scene_0000_02" in commands["prepare"]
    assert (
        "--checkpoint tiny_setdiff" in commands["run setdiff"]
        and "--checkpoint tiny_difix" in commands["run difix"]
    )
    assert summary["test_scenes"] == ["scene_0000_02"]
    assert sorted(p.name for p in (shipped_demo_out / "work" / "scenes").iterdir()) == ["scene_0000_02"]
    assert not (shipped_demo_out / "work" / "checkpoints").exists()
    for method, model in summary["models"].items():
        assert model["shipped"] == f"tiny_{method}" and "scene_0000_02" not in model["trained_on"]
    board = pd.read_parquet(shipped_demo_out / "synthetic.parquet")
    assert set(board["method"]) == set(METHODS) and board["value"].notna().all()
    readme = (shipped_demo_out / "README.md").read_text()
    assert "the shipped model `tiny_setdiff`" in readme and "Test scenes: scene_0000_02" in readme


def test_training_options_need_train(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--preset", "tiny", "--out", str(tmp_path / "d"), "--ablations"]) == 2
    assert "add --train" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()
