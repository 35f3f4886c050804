"""Scoring a finished run under a profile, and tabulating it with the profile in the caption."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.profile_scoring import score_run
from setdiff_bench.io.run_layout import GROUPS_FILE, METRICS_FILE, PROFILE_FILE, PROFILES_DIR
from setdiff_bench.protocols.profiles import EvaluationProfile, get_profile
from setdiff_bench.reporting.leaderboard import (
    LeaderboardError,
    build_leaderboard,
    load_runs,
    render_markdown,
)
from tests.evaluation.run.store_fixtures import leaderboard_argv


@pytest.fixture
def run_copy(identity_run: Path, tmp_path: Path) -> Path:
    """A private copy of the shared run (profile tables are written inside the run folder)."""
    return Path(shutil.copytree(identity_run, tmp_path / "identity"))


def test_paper_profile_reproduces_the_runs_own_scores(run_copy: Path, store: Path):
    identity_run = run_copy
    out = score_run(identity_run, get_profile("paper"), packets=store, progress=False)
    own = pd.read_parquet(identity_run / METRICS_FILE).sort_values(["packet_id", "view"])
    rescored = pd.read_parquet(out / METRICS_FILE).sort_values(["packet_id", "view"])
    for metric in ("psnr", "ssim", "lpips"):
        assert np.allclose(rescored[metric], own[metric], rtol=1e-5, atol=1e-6, equal_nan=True), metric
    groups = pd.read_parquet(out / GROUPS_FILE)
    pooled = own.groupby("group")["psnr"].mean()
    assert np.allclose(groups.set_index("group")["psnr"].loc[pooled.index], pooled)
    assert json.loads((out / PROFILE_FILE).read_text())["profile"]["name"] == "paper"


def test_scene_mean_profile_in_the_leaderboard_caption_and_never_mixed(
    run_copy: Path, store: Path, monkeypatch
):
    identity_run = run_copy
    from setdiff_bench.protocols import profiles

    custom = EvaluationProfile(
        "scene_test", "test profile: per-scene means", "", ("psnr",), aggregation="scene_mean"
    )
    monkeypatch.setattr(profiles, "PROFILES", {**profiles.PROFILES, "scene_test": custom})
    score_run(identity_run, custom, packets=store, progress=False)
    images, _ = load_runs(identity_run)
    dataset = images["dataset"].iloc[0]
    board = build_leaderboard(dataset, images, profile="scene_test", metrics=["psnr"])
    assert "evaluation profile: scene_test" in board.title and board.stem == f"{dataset}.scene_test"
    rows = images[images["profile"] == "scene_test"]
    group = board.columns[0][0].key
    block = rows[rows["group"] == group]
    expected = block.groupby("scene")["psnr"].mean().mean()  # mean of scene means
    assert board.rows[0].values[(group, "psnr")] == pytest.approx(expected)
    assert "means over scenes" in render_markdown(board)
    plain = build_leaderboard(dataset, images, metrics=["psnr"])  # default: the plain run rows only
    assert "evaluation profile: paper" in plain.title
    assert plain.rows[0].counts[(group, "psnr")] == len(
        images[images["profile"].isna() & (images["group"] == group)]
    )
    reported = pd.DataFrame({"dataset": [dataset], "metric": ["psnr"]})
    with pytest.raises(LeaderboardError, match="cannot share a table"):
        build_leaderboard(dataset, images, profile="scene_test", metrics=["psnr"], reported=reported)


def test_profiles_needing_the_dataset_say_so(identity_run: Path, store: Path, capsys):
    with pytest.raises(UsageError, match="--data"):
        score_run(identity_run, get_profile("euvs_official"), packets=store, progress=False)
    assert (
        main(["evaluate", str(identity_run), "--profile", "dl3dv_3dgs_enhancer", "--packets", str(store)])
        == 2
    )
    assert "pass the dataset root (--data)" in capsys.readouterr().err
    assert (
        main(
            [
                "evaluate",
                str(identity_run),
                "--profile",
                "euvs_official",
                "--packets",
                str(store),
                "--dinov2",
                str(store / "absent"),
            ]
        )
        == 2
    )
    assert "DINOv2 weights folder not found" in capsys.readouterr().err


def test_evaluate_and_leaderboard_commands(run_copy: Path, store: Path, tmp_path: Path, capsys):
    assert main(["evaluate", str(run_copy), "--profile", "paper", "--packets", str(store)]) == 0
    assert "evaluation profile: paper" in capsys.readouterr().out
    assert (run_copy / PROFILES_DIR / "paper" / GROUPS_FILE).is_file()
    dataset = pd.read_parquet(run_copy / METRICS_FILE)["dataset"].iloc[0]
    out = tmp_path / "boards"
    assert main(leaderboard_argv(dataset, run_copy, out, "--format", "md")) == 0
    assert "evaluation profile: paper" in (out / f"{dataset}.md").read_text()
