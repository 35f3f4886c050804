"""The quality table of SetDiff's speed options (issue 55) from ``benchmarks/speed_options.sh``'s comparisons.

Reads ``WORK/compare/compare_<option>_vs_teacher.parquet`` of each benchmark (``setdiff-bench compare``'s
paired gains over the shipped teacher, intervals resampled by scene; for the restricted-attention fine-tunes
also ``..._vs_finetune``, their gains over the full-attention fine-tune of the same recipe) and writes one JSON with, per benchmark
and option, the gain in PSNR / SSIM / LPIPS (positive = the option better) over every test target and over
the benchmark's verdict group (driving: ``lane+2``, sparse: ``n3``), with its 95 % interval, and prints the
Markdown table of docs/performance.md.

    python benchmarks/speed_options_table.py --work driving=runs/speed/driving --work sparse=runs/speed/sparse \\
        [--out speed_options_quality]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path
from typing import Any

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

from benchmarks.common import write_result  # noqa: E402
from setdiff_bench.pipeline.presets import DEMO_BENCHMARKS  # noqa: E402

METRICS = ("psnr", "ssim", "lpips")
#: The options in the table's order, with what each row says.
OPTIONS = {
    "student": "one-pass student (`--speed fast`)",
    "one_pass": "the teacher run in one pass (guidance 1), untrained",
    "view0": "per-view set attention at level 0, fine-tuned",
    "knn0": "16 nearest reference tokens at level 0, fine-tuned",
    "finetune": "control: the same fine-tune, full attention",
    "student_view0": "student with per-view level 0",
}
TEACHERS = {"driving": "tiny_setdiff", "sparse": "tiny_setdiff_sparse"}
#: Options also compared with the full-attention fine-tune (``finetune``): the restriction's own cost.
RESTRICTED = ("view0", "knn0")


def gains(table: pd.DataFrame, level: str, key: str) -> dict[str, Any]:
    """``{metric: {gain, low, high, holds, option, teacher}}`` of one row of a comparison."""
    rows = table[(table["level"] == level) & (table["key"] == key)].set_index("metric")
    return {
        metric: {
            "gain": float(rows.loc[metric, "gain"]),
            "low": float(rows.loc[metric, "gain_low"]),
            "high": float(rows.loc[metric, "gain_high"]),
            "holds": bool(rows.loc[metric, "holds"]),
            "option": float(rows.loc[metric, "mean_a"]),
            "teacher": float(rows.loc[metric, "mean_b"]),
            "targets": int(rows.loc[metric, "targets"]),
        }
        for metric in METRICS
    }


def cell(entry: dict[str, Any], digits: int) -> str:
    return f"{entry['gain']:+.{digits}f} [{entry['low']:+.{digits}f}, {entry['high']:+.{digits}f}]"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", action="append", required=True, help="BENCHMARK=WORK folder (repeatable)")
    parser.add_argument("--out", default="speed_options_quality")
    args = parser.parse_args()
    result: dict[str, Any] = {
        "issue": 55,
        "command": "bash benchmarks/speed_options.sh BENCHMARK PACKETS WORK; python benchmarks/speed_options_table.py "
        + " ".join(f"--work {w.split('=', 1)[0]}=runs/speed/{w.split('=', 1)[0]}" for w in args.work),
        "revision": subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=False
        ).stdout.strip(),
        "reading": "gain = option - teacher where higher is better, teacher - option where lower is (LPIPS): "
        "positive = the option better; 95 % intervals resampled by scene (2-3 test scenes: see compare)",
        "benchmarks": {},
    }
    lines = [
        "| option | benchmark | targets | PSNR gain (all) | PSNR gain (verdict group) | SSIM gain (group) | LPIPS gain (group) |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for spec in args.work:
        benchmark, folder = spec.split("=", 1)
        group = DEMO_BENCHMARKS[benchmark].verdict_group
        entries = {}
        rows = [(option, "teacher", words) for option, words in OPTIONS.items()]
        rows += [(option, "finetune", f"{OPTIONS[option]}, against the control") for option in RESTRICTED]
        for option, reference, words in rows:
            path = Path(folder) / "compare" / f"compare_{option}_vs_{reference}.parquet"
            if not path.is_file():
                continue
            option = option if reference == "teacher" else f"{option}_vs_finetune"
            table = pd.read_parquet(path)
            entries[option] = {
                "what": words,
                "all": gains(table, "all", ""),
                group: gains(table, "group", group),
            }
            overall, grouped = entries[option]["all"], entries[option][group]
            lines.append(
                f"| {words} | {benchmark} ({group}) | {overall['psnr']['targets']} | {cell(overall['psnr'], 3)} | "
                f"{cell(grouped['psnr'], 3)} | {cell(grouped['ssim'], 4)} | {cell(grouped['lpips'], 4)} |"
            )
        result["benchmarks"][benchmark] = {
            "teacher": TEACHERS[benchmark],
            "verdict_group": group,
            "options": entries,
        }
    print("\n".join(lines))
    print("wrote", write_result(args.out, result))


if __name__ == "__main__":
    main()
