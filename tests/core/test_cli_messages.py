"""What a newcomer reads: help examples one per line, one error prefix per verb, unknown names listed."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.loaders import DATASETS
from setdiff_bench.reporting.leaderboard import build_leaderboard


def test_help_keeps_examples_on_their_own_lines(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["prepare", "--help"])
    text = capsys.readouterr().out
    lines = text.splitlines()
    examples = [line.strip() for line in lines if line.strip().startswith("setdiff-bench prepare ")]
    assert len(examples) >= 3 and all(
        line.startswith("    setdiff-bench prepare") for line in lines if line.strip() in examples
    )
    assert "Examples:" in text and "Examples::" not in text and "``" not in text
    assert not any("  --" in line for line in examples)  # a continuation joined into one line, not a gap


def test_one_error_prefix_for_usage_and_runtime_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as usage:
        main(["list", "scenes"])
    assert usage.value.code == 2
    assert capsys.readouterr().err.startswith(
        "setdiff-bench list: error: the following arguments are required"
    )
    assert main(["list", "scenes", "--dataset", "euvs", "--root", str(tmp_path / "missing")]) == 2
    assert capsys.readouterr().err.startswith("setdiff-bench list: error: ")


def test_unknown_dataset_lists_the_known_ones(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # prepare's dataset positional takes its choices from the loader registry: argparse refuses it (issue 45)
    argv = [
        "prepare",
        "kitti",
        "--root",
        str(tmp_path),
        "--fits",
        str(tmp_path),
        "--out",
        str(tmp_path / "p"),
    ]
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    error = capsys.readouterr().err
    assert "invalid choice: 'kitti'" in error and all(key in error for key in DATASETS)
    assert not (tmp_path / "p").exists()
    assert (
        main(["leaderboard", "--dataset", "euvz", "--runs", str(tmp_path), "--out", str(tmp_path / "lb")])
        == 2
    )
    error = capsys.readouterr().err
    assert "unknown dataset 'euvz'; choose from" in error and all(key in error for key in DATASETS)


def test_leaderboard_names_what_there_is() -> None:
    rows = pd.DataFrame(
        {
            "dataset": ["synthetic"] * 2,
            "split": ["test"] * 2,
            "method": ["identity", "setdiff"],
            "group": ["lane+1"] * 2,
            "psnr": [20.0, 21.0],
            "ssim": [0.5, 0.6],
            "lpips": [0.3, 0.2],
        }
    )
    with pytest.raises(Exception, match="runs found for: synthetic"):
        build_leaderboard("euvs", rows)
    with pytest.raises(Exception, match="splits with results: test"):
        build_leaderboard("synthetic", rows, split="val")
    with pytest.raises(Exception, match="methods with runs: identity, setdiff"):
        build_leaderboard("synthetic", rows, methods=["difix"])


def test_readme_links_only_files_in_the_repository() -> None:
    root = Path(__file__).resolve().parents[2]
    text = (root / "README.md").read_text(encoding="utf-8")
    assert "shared/" not in text
    targets = [t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", text) if "://" not in t]
    assert targets and all((root / target).exists() for target in targets), targets
