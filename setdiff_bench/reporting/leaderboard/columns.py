"""What a leaderboard's columns are: the dataset's layout (its blocks), the pooled and cost blocks, and each
metric's header, decimals and direction as read from its :class:`~setdiff_bench.metrics.registry.MetricSpec`;
and the package's error."""

from __future__ import annotations

from dataclasses import dataclass

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.protocols import POOLED, Layout, list_protocols, load_protocol

ALL = POOLED  # block key of the pooled block (every group)


class LeaderboardError(SetDiffBenchError):
    """Runs that cannot be put in one table (missing rows, duplicates, no data)."""


def dataset_layout(dataset: str) -> Layout:
    """The table shape of ``dataset``: the ``[leaderboard]`` table of its default protocol
    (``protocols/<dataset>.toml``); one block per group found when it has none (or no packaged protocol).

    Raises:
        ProtocolError: the default protocol file is invalid.
    """
    if dataset not in list_protocols():
        return Layout(None)
    layout = load_protocol(dataset).leaderboard
    return layout if layout is not None else Layout(None)


#: Block key of the cost columns (``cost=True``): what enhancing took, beside what it scored.
COST = "cost"


@dataclass(frozen=True)
class CostColumn:
    """A column of the cost block, read from every run's per-target timing columns (lower is better).

    Attributes:
        label: column header; decimals: digits printed; aggregate: how a method's targets reduce to one
            value (``median``: robust to the first packet's warm-up; ``max``: the peak; ``scene_mean``: the
            mean over scenes of a value each scene's targets share).
    """

    label: str
    decimals: int
    aggregate: str


#: The cost block: ms per target frame (median over the method's targets, warm) and peak memory (CUDA max
#: allocated or peak resident memory, the largest over its packets), as ``run`` records them; for the runs of
#: refitted scenes (``run --refit``), the refit's wall seconds per scene (``refit_s``, from the run's manifest).
COST_COLUMNS: dict[str, CostColumn] = {
    "ms_per_frame": CostColumn("ms/frame", 0, "median"),
    "peak_memory_mb": CostColumn("peak MiB", 0, "max"),
    "refit_s": CostColumn("refit s/scene", 0, "scene_mean"),
}


def metric_header(name: str) -> str:
    """The column header of metric ``name`` (``MetricSpec.label``: ``psnr_euvs`` → ``PSNR``)."""
    return COST_COLUMNS[name].label if name in COST_COLUMNS else get_metric(name).label


def metric_decimals(name: str) -> int:
    """Digits after the point that tables print for metric ``name`` (``MetricSpec.decimals``)."""
    return COST_COLUMNS[name].decimals if name in COST_COLUMNS else get_metric(name).decimals


def higher_is_better(name: str) -> bool:
    """Ranking direction of metric ``name`` (``MetricSpec.higher_is_better``; costs: lower is better)."""
    return False if name in COST_COLUMNS else get_metric(name).higher_is_better


def metric_arrow(metric: str, latex: bool) -> str:
    """The metric's direction arrow (``MetricSpec.arrow``), in LaTeX math where asked."""
    if metric in COST_COLUMNS:
        return r"$\downarrow$" if latex else "↓"
    spec = get_metric(metric)
    if latex:
        return r"$\uparrow$" if spec.higher_is_better else r"$\downarrow$"
    return spec.arrow
