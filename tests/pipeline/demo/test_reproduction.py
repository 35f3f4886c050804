"""The demo's comparison with the published table (pipeline/reproduction.py), on hand-made leaderboards."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.pipeline.presets import DEMO_BENCHMARKS
from setdiff_bench.pipeline.reproduction import (
    RESULTS_FOLDER,
    Reproduction,
    check_reproduction,
    compare_tables,
)

TOLERANCE = {"psnr": 0.01, "ssim": 0.0001, "lpips": 0.0001}


def board(values: dict[tuple[str, str, str], float], reported: bool = False) -> pd.DataFrame:
    rows = [
        {"source": "measured", "method": m, "block": b, "metric": k, "value": v}
        for (m, b, k), v in values.items()
    ]
    if reported:  # the paper's rows are never compared
        rows.append({"source": "reported", "method": "3dgs", "block": "n3", "metric": "psnr", "value": 10.97})
    return pd.DataFrame(rows)


BASE = {
    ("identity", "lane+2", "psnr"): 17.89,
    ("setdiff", "lane+2", "psnr"): 21.56,
    ("setdiff", "lane+2", "ssim"): 0.769,
    ("setdiff", "lane+2", "lpips"): 0.156,
}


def test_equal_cells_are_identical_and_reported_rows_are_ignored():
    result = compare_tables(board(BASE), board(BASE, reported=True), TOLERANCE)
    assert result.status == "identical"
    assert result.line().startswith("reproduction: identical to the published table")


def test_differences_within_the_tolerance():
    moved = {**BASE, ("setdiff", "lane+2", "psnr"): 21.56 + 0.004, ("setdiff", "lane+2", "lpips"): 0.15605}
    result = compare_tables(board(moved), board(BASE), TOLERANCE)
    assert result.status == "within" and not result.outside
    assert result.largest["psnr"] == pytest.approx(0.004)
    assert result.largest["lpips"] == pytest.approx(0.00005)
    assert "within the stated tolerance" in result.line() and "psnr 0.01" in result.line()


def test_cells_outside_the_tolerance_are_named():
    moved = {**BASE, ("identity", "lane+2", "psnr"): 18.00}
    result = compare_tables(board(moved), board(BASE), TOLERANCE)
    assert result.status == "outside"
    assert result.outside == [("identity", "lane+2", "psnr", 18.00, 17.89)]
    assert "OUTSIDE" in result.line() and "identity lane+2 psnr 18.0000 vs 17.8900" in result.line()


def test_the_line_names_only_the_largest_cells():
    moved = {key: value + 1.0 + i for i, (key, value) in enumerate(BASE.items())}
    moved.update({("identity", f"b{i}", "psnr"): 10.0 + i for i in range(6)})
    theirs = {**BASE, **{("identity", f"b{i}", "psnr"): 10.0 for i in range(6)}}
    line = compare_tables(board(moved), board(theirs), TOLERANCE).line()
    assert "the 5 largest of 9" in line and "identity b5 psnr 15.0000 vs 10.0000" in line
    assert "identity b0" not in line  # equal cells are not outside


def test_another_set_of_cells_is_not_comparable():
    fewer = {key: value for key, value in BASE.items() if key[0] == "setdiff"}
    result = compare_tables(board(fewer), board(BASE), TOLERANCE)
    assert result.status == "not comparable" and "missing" in result.reason


def test_json_round_trip():
    result = compare_tables(board({**BASE, ("identity", "lane+2", "psnr"): 18.0}), board(BASE), TOLERANCE)
    assert Reproduction.from_json(json.loads(json.dumps(result.as_json()))).line() == result.line()


def _published(folder: Path, command: str) -> Path:
    (folder / "synthetic").mkdir(parents=True)
    board(BASE).to_parquet(folder / "synthetic" / "synthetic.parquet")
    provenance = {"run_command": command, "seed": 0}
    (folder / "synthetic" / "provenance.json").write_text(json.dumps(provenance), encoding="utf-8")
    return folder


def test_check_reproduction_compares_only_the_published_preset_and_seed(tmp_path):
    results = _published(tmp_path / "results", "setdiff-bench demo --preset default --out runs/demo --seed 0")
    out = tmp_path / "run"
    out.mkdir()
    board(BASE).to_parquet(out / "synthetic.parquet")
    driving = DEMO_BENCHMARKS["driving"]
    assert check_reproduction(driving, "default", 0, out, results).status == "identical"
    other = check_reproduction(driving, "tiny", 0, out, results)
    assert other.status == "not comparable" and "--preset default --seed 0" in other.reason
    missing = check_reproduction(driving, "default", 0, out, tmp_path / "nowhere")
    assert missing.status == "not comparable" and "source checkout" in missing.reason


@pytest.mark.parametrize("name", sorted(DEMO_BENCHMARKS))
def test_each_benchmark_has_its_own_folder_and_a_published_run(name):
    benchmark = DEMO_BENCHMARKS[name]
    assert benchmark.default_out.startswith("runs/")
    assert (RESULTS_FOLDER / benchmark.published / f"{benchmark.leaderboard}.parquet").is_file()
    assert set(benchmark.tolerance) == {"psnr", "ssim", "lpips"}
    others = [b.default_out for b in DEMO_BENCHMARKS.values() if b is not benchmark]
    others += [b.refit.default_out for b in DEMO_BENCHMARKS.values()]
    assert benchmark.default_out not in others
    assert (
        benchmark.refit.default_out.startswith("runs/") and benchmark.refit.published != benchmark.published
    )


@pytest.mark.parametrize("name", sorted(DEMO_BENCHMARKS))
def test_each_refit_demo_is_published_with_every_comparison(name):
    benchmark = DEMO_BENCHMARKS[name]
    published = RESULTS_FOLDER / benchmark.refit.published
    assert (published / f"{benchmark.leaderboard}.parquet").is_file()
    assert (published / f"{benchmark.leaderboard}_refit_steps.png").is_file()
    # identity-3D vs identity, and four per other enhancer (demo._stages.REFIT_COMPARISONS)
    assert len(list(published.glob("compare_*.parquet"))) == 13
    readme = (published / "README.md").read_text(encoding="utf-8")
    assert all(f"### {group} (" in readme for group in benchmark.refit.groups)
