"""An ablation against the paper's ordering: which row is best, and whether each larger or richer setting
beats the smaller one per model (paired gains, seed spreads) and over targets (paired intervals)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import pandas as pd

from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.reporting.ablation._design import METRICS
from setdiff_bench.reporting.ablation._results import Key, paired_over_targets, seed_spread
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.paired import PairedDifference, few_scenes_note


def ordering_geometry(
    frame: pd.DataFrame,
    per_model: Sequence[Mapping[str, Mapping[str, float]]] = (),
    settings: BootstrapSettings | None = None,
) -> list[str]:
    """Plain-language comparison with the paper's Table 5 ordering (None worst, Both best).  With both
    rows present, each metric also compares Both with None; with two or more ``per_model`` results
    (``variant key`` → metric → value, one mapping per training seed) that line gives every model's own
    paired gain, in how many models Both is better and whether the mean gain is beyond the seed spreads;
    when the results carry their per-target rows (:class:`RunMeans`) it also gives the paired interval over
    targets (:func:`paired_over_targets`, drawn as ``settings`` says)."""
    notes = []
    by = frame.set_index("variant")
    for metric in METRICS:
        values, spec = by[metric], get_metric(metric)
        better = values.idxmax() if spec.higher_is_better else values.idxmin()
        worse = values.idxmin() if spec.higher_is_better else values.idxmax()
        notes.append(
            f"{spec.label}: best {by.loc[better, 'grounding']}, worst {by.loc[worse, 'grounding']} "
            f"(paper: best Both, worst None)"
        )
    if not {"both", "none"} <= set(by.index):
        return notes
    over_targets = paired_over_targets(per_model, "both", "none", settings)
    for metric in METRICS:
        spec = get_metric(metric)
        sign = 1.0 if spec.higher_is_better else -1.0
        both, none = float(by.loc["both", metric]), float(by.loc["none", metric])
        per_seed = _paired_gains(per_model, "both", "none", metric, sign)
        per_seed += _target_gain(over_targets, metric)
        notes.append(
            f"{spec.label}: Both vs None {'better' if sign * (both - none) > 0 else 'not better'} "
            f"({both:.4f} vs {none:.4f}{per_seed}; paper: better)"
        )
    return notes + _interval_notes([over_targets], len(per_model), settings)


def ordering_setsize(
    results: Mapping[tuple[int, int], Mapping[str, float]],
    per_model: Sequence[Mapping[tuple[int, int], Mapping[str, float]]] = (),
    settings: BootstrapSettings | None = None,
) -> list[str]:
    """Whether more references / more targets help, as in the paper's Table 6.  ``results`` holds the means;
    with two or more ``per_model`` results each comparison also gives every model's own (paired) gain, in
    how many models the larger set is better and whether the mean gain is beyond the seed spreads; results
    that carry their per-target rows (:class:`RunMeans`) add the paired interval over targets."""
    comparisons = (  # (larger set, smaller set, what the paper found)
        ((3, 1), (1, 1), "better"),
        ((3, 6), (3, 1), "better for PSNR/SSIM, LPIPS within 0.001"),
    )
    over_targets = {
        (new, old): paired_over_targets(per_model, new, old, settings)
        for new, old, _ in comparisons
        if new in results and old in results
    }
    notes = []
    for metric in METRICS:
        label = get_metric(metric).label
        sign = 1.0 if get_metric(metric).higher_is_better else -1.0
        for new_size, old_size, paper in comparisons:
            new, old = results.get(new_size), results.get(old_size)
            if new and old:
                gain = sign * (new[metric] - old[metric])
                per_seed = _paired_gains(per_model, new_size, old_size, metric, sign)
                per_seed += _target_gain(over_targets[(new_size, old_size)], metric)
                notes.append(
                    f"{label}: {new_size[0]}+{new_size[1]} vs {old_size[0]}+{old_size[1]} "
                    f"{'better' if gain > 0 else 'not better'} "
                    f"({new[metric]:.4f} vs {old[metric]:.4f}{per_seed}; paper: {paper})"
                )
    return notes + _interval_notes(list(over_targets.values()), len(per_model), settings)


def _paired_gains(
    per_model: Sequence[Mapping[Key, Mapping[str, float]]], new: Key, old: Key, metric: str, sign: float
) -> str:
    """``"; gain per model +0.1000, -0.0200, better in 1 of 2"``: each model's own ``new`` − ``old`` gain
    (``sign`` −1 for lower-is-better metrics) and in how many models ``new`` is better; empty for one model."""
    paired = [
        sign * (model[new][metric] - model[old][metric])
        for model in per_model
        if new in model and old in model
    ]
    if len(paired) < 2:
        return ""
    mean_gain = sum(paired) / len(paired)
    spreads = [seed_spread(per_model, new, metric), seed_spread(per_model, old, metric)]
    beyond = (
        f"mean gain beyond both seed spreads ({spreads[0]:.4f}, {spreads[1]:.4f})"
        if abs(mean_gain) > max(spreads)
        else f"mean gain within the seed spread ({max(spreads):.4f})"
    )
    return (
        f"; gain per model {', '.join(f'{g:+.4f}' for g in paired)}, "
        f"better in {sum(g > 0 for g in paired)} of {len(paired)}, {beyond}"
    )


def _target_gain(over_targets: Mapping[str, PairedDifference] | None, metric: str) -> str:
    """``"; over 252 targets +0.3450 [+0.2900, +0.4000] (holds), better in 3 of 3 scenes"``: the paired gain
    over targets (positive = better, whatever the metric's direction) and its interval; empty without one."""
    if over_targets is None:
        return ""
    d = over_targets[metric]
    sign = 1.0 if get_metric(metric).higher_is_better else -1.0
    low, high = sorted((sign * d.low, sign * d.high))
    interval = f"[{low:+.4f}, {high:+.4f}]" if d.has_interval else "[n/a]"
    return (
        f"; paired gain over {d.targets} targets {sign * d.difference:+.4f} {interval} "
        f"({'holds' if d.holds else 'interval includes 0'}), better in {d.wins} of {d.scenes} scenes"
    )


def _interval_notes(
    found: Sequence[Mapping[str, PairedDifference] | None], models: int, settings: BootstrapSettings | None
) -> list[str]:
    """How the paired gains over targets were computed, and the few-scenes caveat; none without any."""
    present = [d for d in found if d is not None]
    if not present:
        return []
    averaged = f"each target's gain averaged over the {models} models, " if models > 1 else ""
    notes = [f"Paired gains over targets: {averaged}{(settings or BootstrapSettings()).describe()}."]
    caveat = few_scenes_note(min(d.scenes for found_ in present for d in found_.values()))
    return notes + ([caveat] if caveat else [])
