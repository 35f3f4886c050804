"""The report site's per-scene breakdown: each method's gain over the baseline (the render) per group and
scene, with paired bootstrap intervals (:mod:`setdiff_bench.reporting.paired`, the code behind
``leaderboard --against`` and the ablation tables).

Rows, per dataset and group (and "all groups" when there are several): one per scene, its interval drawn by
resampling that scene's targets (``unit="frame"``: the spread of this scene's frames, which share a fit and
are not independent views of the world), then "all scenes", its interval drawn by resampling whole scenes
(``unit="scene"``) with the number of scenes the method wins.  Gains carry the sign of "better" (positive
helps, whatever the metric's direction: :mod:`setdiff_bench.reporting.gains`), as everywhere in the site.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from setdiff_bench.loaders.common import natural_key
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.gains import GAIN_CONVENTION, PairedGain
from setdiff_bench.reporting.leaderboard import metric_decimals
from setdiff_bench.reporting.paired import few_scenes_note, pair_targets, paired_differences
from setdiff_bench.reporting.site._html import esc, metric_label

#: The columns that pair a method's target with the baseline's (``scene`` is needed by the bootstrap).
PAIR_KEYS = ("dataset", "group", "scene", "packet_id", "view")
#: The label of the rows pooling every scene (and the section pooling every group).
ALL_SCENES = "all scenes"
ALL_GROUPS = "all groups"


def scene_gains(
    method_rows: pd.DataFrame,
    baseline_rows: pd.DataFrame,
    metrics: Sequence[str],
    settings: BootstrapSettings,
) -> dict[str, dict[str, PairedGain]]:
    """Row label (each scene, then :data:`ALL_SCENES`) → metric → :class:`PairedGain` of the method over
    the baseline, on the targets both have.

    ``method_rows`` / ``baseline_rows``: the method's and the baseline's per-image rows of one dataset and
    group (or of all its groups)."""
    pairs = pair_targets(method_rows, baseline_rows, metrics, keys=PAIR_KEYS, names=("method", "baseline"))
    if not len(pairs):
        return {}
    out: dict[str, dict[str, PairedGain]] = {}
    within = dataclasses.replace(settings, unit="frame")
    for scene in sorted(pairs["scene"].unique(), key=natural_key):
        differences = paired_differences(pairs[pairs["scene"] == scene], metrics, within)
        out[str(scene)] = {m: PairedGain.of(d) for m, d in differences.items()}
    pooled = paired_differences(pairs, metrics, dataclasses.replace(settings, unit="scene"))
    out[ALL_SCENES] = {m: PairedGain.of(d) for m, d in pooled.items()}
    return out


def _cell(gain: PairedGain | None, metric: str, pooled: bool) -> str:
    if gain is None or not math.isfinite(gain.value):
        return "<td>–</td>"
    digits = metric_decimals(metric) + 1
    text = gain.format(digits)
    value, interval = text.split(" ", 1)
    difference = gain.difference
    wins = f" · better in {difference.wins}/{difference.scenes} scenes" if pooled else ""
    css = (' class="good"' if gain.value > 0 else ' class="bad"') if gain.holds else ""
    return (
        f'<td data-v="{gain.value}" data-low="{gain.low}" data-high="{gain.high}"{css}>{value}'
        f"<br><small>{interval}{wins}</small></td>"
    )


def scene_table_html(
    plain: pd.DataFrame,
    labels: Mapping[str, Path],
    methods: Sequence[str],
    metrics: Sequence[str],
    baseline: str,
    settings: BootstrapSettings,
) -> str:
    """Per dataset: a table of each method's gain per group and scene with its paired interval (see the
    module docstring), and a note saying how the intervals were drawn.

    Args:
        plain: the runs' per-image rows of one profile and split (``run``, ``dataset``, ``group``,
            ``scene``, ``packet_id``, ``view`` and the metric columns).
        labels: method label → run folder (``plain["run"]`` holds the folders as strings).
        methods: labels of the methods shown, baseline included or not (it gets no column).
        metrics: the metric columns.
        baseline: the label of the run gains are measured against.
        settings: resamples, level and seed of the intervals.
    """
    compared = [m for m in methods if m != baseline]
    runs = {label: str(folder) for label, folder in labels.items()}
    if not compared or baseline not in runs:
        return ""
    parts = []
    for dataset in sorted(plain["dataset"].unique()):
        frame = plain[plain["dataset"] == dataset]
        groups = sorted(frame["group"].unique(), key=natural_key)
        sections = [(str(g), frame[frame["group"] == g]) for g in groups]
        if len(groups) > 1:
            sections.append((ALL_GROUPS, frame))
        header_methods = "".join(f'<th colspan="{len(metrics)}">{esc(m)}</th>' for m in compared)
        header_metrics = "".join(
            f"<th>{esc(metric_label(metric, ' gain', arrow=False))}</th>"
            for _ in compared
            for metric in metrics
        )
        body = []
        scene_count = frame["scene"].nunique()
        for group, rows in sections:
            base = rows[rows["run"] == runs[baseline]]
            gains = {
                method: scene_gains(rows[rows["run"] == runs[method]], base, metrics, settings)
                for method in compared
            }
            labels_in_order = list(dict.fromkeys(label for g in gains.values() for label in g))
            for label in labels_in_order:
                pooled = label == ALL_SCENES
                cells = "".join(
                    _cell(gains[method].get(label, {}).get(metric), metric, pooled)
                    for method in compared
                    for metric in metrics
                )
                counts = [g.difference.targets for m in compared for g in gains[m].get(label, {}).values()]
                count = f"<br><small>{max(counts)} targets</small>" if counts else ""
                name = f"<b>{esc(label)}</b>" if pooled else esc(label)
                body.append(
                    f'<tr><td class="l">{esc(group)}</td><td class="l">{name}{count}</td>{cells}</tr>'
                )
        note = few_scenes_note(scene_count)
        parts.append(
            f'<table class="scenes"><caption>{esc(dataset)}: gain over {esc(baseline)} (the render) per '
            f"scene, with {settings.confidence * 100:g} % paired bootstrap intervals</caption><thead><tr>"
            f'<th class="l" rowspan="2">group</th><th class="l" rowspan="2">scene</th>{header_methods}</tr>'
            f"<tr>{header_metrics}</tr></thead><tbody>{''.join(body)}</tbody></table>"
            + (f'<p class="note">{esc(note)}</p>' if note else "")
        )
    explain = (
        f"A = the method, B = {baseline}; {GAIN_CONVENTION}.  Per scene, the interval resamples that scene's targets (they share one fit, so it shows "
        "the spread of this scene's frames, not certainty about other views); on the all-scenes rows it "
        "resamples whole scenes, and the count says in how many scenes the mean gain is positive.  Green "
        f"or red: the interval excludes 0.  Intervals: {dataclasses.replace(settings, unit='scene').describe()}"
        "; within a scene the same over its targets."
    )
    return "".join(parts) + f'<p class="note">{esc(explain)}</p>'
