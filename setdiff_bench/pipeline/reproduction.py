"""Does a demo's leaderboard equal the published one?  One line: identical, within tolerance, or outside.

The published run of each embedded benchmark lives in the source checkout (``results/synthetic/``,
``results/synthetic_sparse/``: its leaderboard parquet and ``provenance.json``).  A demo run with the same
benchmark, preset and seed is compared with it cell by cell (method × block × metric, the paper's reported
rows left out), on the full-precision values of the long-format leaderboard parquet:

* **identical**: every cell equal;
* **within tolerance**: every cell within the benchmark's measured tolerance
  (:attr:`setdiff_bench.pipeline.presets.DemoBenchmark.tolerance`: the largest difference measured
  between instruction sets and thread counts, docs/reproducibility.md);
* **outside tolerance**: the cells that are not, with both values.

A run that cannot be compared (another preset or seed, no published folder beside the package, another
set of cells) says why instead.
"""

from __future__ import annotations

import itertools
import json
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from setdiff_bench.pipeline.presets import DemoBenchmark

#: Where the published results live, relative to the package folder (a source checkout).
RESULTS_FOLDER = Path(__file__).resolve().parents[2] / "results"
KEYS = ["method", "block", "metric"]
#: Cells beyond the tolerance that the printed line names (the largest differences; demo.json has all).
SHOWN_CELLS = 5


@dataclass
class Reproduction:
    """The outcome of comparing a demo's leaderboard with the published one.

    Attributes:
        status: ``identical``, ``within``, ``outside`` or ``not comparable``.
        reason: why not comparable (empty otherwise).
        published: the published folder compared with (relative to the checkout when possible).
        largest: ``{metric: largest absolute difference}`` over the compared cells.
        outside: ``[(method, block, metric, ours, published)]`` for the cells beyond the tolerance.
        tolerance: ``{metric: tolerance}`` used.
    """

    status: str
    reason: str = ""
    published: str = ""
    largest: dict[str, float] = field(default_factory=dict)
    outside: list[tuple[str, str, str, float, float]] = field(default_factory=list)
    tolerance: dict[str, float] = field(default_factory=dict)

    def line(self) -> str:
        """The one line the demo prints."""
        where = f"the published table ({self.published})"
        if self.status == "not comparable":
            return f"reproduction: not compared with {where}: {self.reason}"
        if self.status == "identical":
            return f"reproduction: identical to {where}, every cell equal"
        largest = ", ".join(f"{metric} {value:.2g}" for metric, value in sorted(self.largest.items()))
        stated = ", ".join(f"{metric} {value:g}" for metric, value in sorted(self.tolerance.items()))
        if self.status == "within":
            return f"reproduction: within the stated tolerance of {where} ({stated}); largest differences: {largest}"
        worst = sorted(self.outside, key=lambda cell: -abs(cell[3] - cell[4]))[:SHOWN_CELLS]
        cells = "; ".join(
            f"{method} {block} {metric} {ours:.4f} vs {theirs:.4f}"
            for method, block, metric, ours, theirs in worst
        )
        more = (
            f" (the {len(worst)} largest of {len(self.outside)}; all in demo.json)"
            if len(self.outside) > len(worst)
            else ""
        )
        return f"reproduction: OUTSIDE the stated tolerance of {where} ({stated}): {cells}{more}"

    @classmethod
    def from_json(cls, record: dict[str, Any]) -> Reproduction:
        """The inverse of :meth:`as_json` (``demo.json``'s ``reproduction``)."""
        return cls(
            status=record["status"],
            reason=record.get("reason", ""),
            published=record.get("published", ""),
            largest=dict(record.get("largest_difference", {})),
            outside=[tuple(cell) for cell in record.get("outside", [])],
            tolerance=dict(record.get("tolerance", {})),
        )

    def as_json(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "reason": self.reason,
            "published": self.published,
            "largest_difference": self.largest,
            "outside": [list(cell) for cell in self.outside],
            "tolerance": self.tolerance,
        }


def _command_options(command: str) -> dict[str, str]:
    """``{--option: value}`` of a recorded ``setdiff-bench demo ...`` command line."""
    words = shlex.split(command)
    return {word: value for word, value in itertools.pairwise(words) if word.startswith("--")}


def _cells(table: pd.DataFrame) -> pd.Series:
    """The measured cells of a long-format leaderboard, indexed by (method, block, metric)."""
    measured = table[table["source"] == "measured"] if "source" in table.columns else table
    return measured.set_index(KEYS)["value"].astype(float).sort_index()


def compare_tables(ours: pd.DataFrame, published: pd.DataFrame, tolerance: dict[str, float]) -> Reproduction:
    """Compare two long-format leaderboards (``method, block, metric, value`` columns) cell by cell.

    Args:
        tolerance: largest allowed absolute difference per metric (metrics not listed must be equal).
    """
    mine, theirs = _cells(ours), _cells(published)
    if set(mine.index) != set(theirs.index):
        missing = sorted(set(theirs.index) - set(mine.index))[:3]
        extra = sorted(set(mine.index) - set(theirs.index))[:3]
        return Reproduction(
            "not comparable", f"other cells (missing {missing}, extra {extra})", tolerance=tolerance
        )
    mine = mine.loc[theirs.index]
    difference = (mine - theirs).abs()
    largest = {
        metric: float(values.max()) for metric, values in difference.groupby(level="metric") if len(values)
    }
    if (difference == 0).all():
        return Reproduction("identical", largest=largest, tolerance=tolerance)
    allowed = pd.Series([tolerance.get(key[2], 0.0) for key in difference.index], index=difference.index)
    beyond = difference > allowed
    outside = [(*key, float(mine[key]), float(theirs[key])) for key in difference.index[beyond.to_numpy()]]
    return Reproduction(
        "outside" if outside else "within", largest=largest, outside=outside, tolerance=tolerance
    )


def check_reproduction(
    benchmark: DemoBenchmark,
    preset: str,
    seed: int,
    out: Path,
    results: Path = RESULTS_FOLDER,
    *,
    refit: bool = False,
) -> Reproduction:
    """Compare the demo table in ``out`` with ``results/<benchmark.published>`` (``refit``: the ``demo --refit``
    folder, ``benchmark.refit.published``) when they are comparable."""
    published = benchmark.refit.published if refit else benchmark.published
    folder = results / published
    shown = f"results/{published}"
    tolerance = dict(benchmark.tolerance)
    table_name = f"{benchmark.leaderboard}.parquet"
    provenance_file = folder / "provenance.json"
    if not (folder / table_name).is_file() or not provenance_file.is_file():
        reason = "no published results beside the package (they are part of the source checkout)"
        return Reproduction("not comparable", reason, shown, tolerance=tolerance)
    provenance = json.loads(provenance_file.read_text(encoding="utf-8"))
    options = _command_options(provenance.get("run_command", ""))
    published_preset = options.get("--preset", "default")
    published_seed = int(provenance.get("seed", options.get("--seed", 0)))
    if (published_preset, published_seed) != (preset, seed):
        reason = f"it was made with --preset {published_preset} --seed {published_seed}"
        return Reproduction("not comparable", reason, shown, tolerance=tolerance)
    result = compare_tables(
        pd.read_parquet(out / table_name), pd.read_parquet(folder / table_name), tolerance
    )
    result.published = shown
    return result
