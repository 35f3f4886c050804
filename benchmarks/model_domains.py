"""Which shipped model to run on what: every model on every embedded benchmark (issue 37's 2×2 table).

Each cell is a model's mean PSNR / SSIM / LPIPS over one benchmark's test targets (all groups, and the
benchmark's verdict group: ``lane+2`` for driving, ``n3`` for sparse), beside the raw render's (``identity``)
on the same targets, with the paired difference to the render and its 95 % scene-bootstrap interval
(:func:`setdiff_bench.reporting.paired.paired_differences`; with 2 test scenes per benchmark the interval
has little to resample and says so).  The runs are ordinary ``setdiff-bench run`` folders::

    setdiff-bench run --method setdiff --checkpoint tiny_setdiff_sparse --packets <driving store> \\
        --split test --out runs/domains/driving/tiny_setdiff_sparse
    python benchmarks/model_domains.py \\
        --benchmark driving=runs/demo/work/runs/identity --benchmark sparse=runs/sparse/runs/identity \\
        --run driving:tiny_setdiff=runs/demo/work/runs/setdiff ... \\
        --out benchmarks/results/model_domains.json

Pandas does the grouping; the one thing written here is the table layout.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import pandas as pd

from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.pipeline.presets import DEMO_BENCHMARKS
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.paired import pair_targets, paired_differences

METRICS = ("psnr", "ssim", "lpips")
#: What the 2×2 table of issue 37 answers (the default ``--question``).
DOMAINS_QUESTION = (
    "which shipped model to run on which embedded benchmark: each model's scores on each "
    "benchmark's test targets against the raw render"
)
#: The group each benchmark's verdict is taken on, as the demo declares it.
VERDICT_GROUPS = {name: benchmark.verdict_group for name, benchmark in DEMO_BENCHMARKS.items()}


def read_run(folder: Path) -> pd.DataFrame:
    """A run folder's per-target rows of the test split."""
    rows = pd.read_parquet(folder / METRICS_FILE)
    return rows[rows["split"] == "test"]


def cell(model: pd.DataFrame, render: pd.DataFrame, settings: BootstrapSettings) -> dict[str, Any]:
    """Means of ``model`` and of the render on the same targets, the paired difference and its interval."""
    pairs = pair_targets(model, render, METRICS, names=("model", "render"))
    differences = paired_differences(pairs, METRICS, settings)
    out: dict[str, Any] = {"targets": len(pairs)}
    for metric in METRICS:
        d = differences[metric]
        out[metric] = {
            "model": d.mean_a,
            "render": d.mean_b,
            "difference": d.difference,
            "interval_95": [d.low, d.high],
            "scenes_won_tied_lost": [d.wins, d.ties, d.losses],
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--benchmark", action="append", required=True, metavar="NAME=IDENTITY_RUN")
    parser.add_argument("--run", action="append", required=True, metavar="BENCHMARK:MODEL=RUN")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--resamples", type=int, default=10_000)
    parser.add_argument("--issue", type=int, default=37, help="the issue the table answers (recorded)")
    parser.add_argument(
        "--question", default=DOMAINS_QUESTION, help="the question the table answers (recorded)"
    )
    args = parser.parse_args()
    settings = BootstrapSettings(resamples=args.resamples, seed=0)
    renders = {name: read_run(Path(path)) for name, path in (b.split("=", 1) for b in args.benchmark)}
    table: dict[str, dict[str, Any]] = {}
    for spec in args.run:
        where, path = spec.split("=", 1)
        benchmark, model = where.split(":", 1)
        rows, render = read_run(Path(path)), renders[benchmark]
        group = VERDICT_GROUPS[benchmark]
        table.setdefault(model, {})[benchmark] = {
            "run": path,
            "all": cell(rows, render, settings),
            group: cell(rows[rows["group"] == group], render[render["group"] == group], settings),
        }
    payload = {
        "benchmark": "model_domains",
        "issue": args.issue,
        "question": args.question,
        "verdict_groups": VERDICT_GROUPS,
        "bootstrap": {"resamples": args.resamples, "seed": 0, "unit": "scene", "level": 0.95},
        "models": table,
    }
    args.out.write_text(json.dumps(payload, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(markdown(table))


def markdown(table: dict[str, dict[str, Any]]) -> str:
    """The 2×2 table: one row per model, per benchmark PSNR / SSIM / LPIPS on its verdict group with the
    difference to the render in brackets."""
    benchmarks = list(VERDICT_GROUPS)
    head = " | ".join(f"{b} ({VERDICT_GROUPS[b]}) PSNR / SSIM / LPIPS" for b in benchmarks)
    lines = [f"| model | {head} |", "|---|" + "---|" * len(benchmarks)]
    for model, cells in table.items():
        parts = []
        for benchmark in benchmarks:
            if benchmark not in cells:
                parts.append("–")
                continue
            c = cells[benchmark][VERDICT_GROUPS[benchmark]]
            parts.append(
                " / ".join(
                    f"{c[m]['model']:.{2 if m == 'psnr' else 3}f} ({c[m]['difference']:+.{2 if m == 'psnr' else 3}f})"
                    for m in METRICS
                )
            )
        lines.append(f"| {model} | " + " | ".join(parts) + " |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
