"""The demo's report (``<out>/README.md``): what ran and how long, the models, the leaderboard, the verdict
table and the files, from the summary :mod:`.demo_summary` makes."""

from __future__ import annotations

from typing import Any

from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.pipeline.demo._layout import DemoPaths
from setdiff_bench.pipeline.demo._stages import METHODS
from setdiff_bench.pipeline.demo._summary import VERDICT_METRICS
from setdiff_bench.pipeline.presets import get_benchmark


def threads_line(summary: dict[str, Any], provenance: dict[str, Any]) -> str:
    """``"2 torch threads"``, or, where stages ran side by side with a share of them,
    ``"2 torch threads (1 each for the 4 stages run side by side)"``: the counts the stages computed with
    (``demo.json``'s per-stage ``threads``; summaries written before they were recorded give the first)."""
    total = provenance["torch_threads"]
    shared = sorted(
        {int(s["threads"]) for s in summary.get("stages", []) if s.get("threads") not in (None, total)}
    )
    if not shared:
        return f"{total} torch threads"
    count = sum(1 for s in summary["stages"] if s.get("threads") not in (None, total))
    each = " or ".join(str(n) for n in shared)
    return f"{total} torch threads ({each} each for the {count} stages run side by side)"


def report_markdown(summary: dict[str, Any], paths: DemoPaths) -> str:
    """``<out>/README.md``: what ran, how long, the leaderboard, the verdict and the files."""
    benchmark = get_benchmark(summary["preset"].get("benchmark", "driving"))
    lines = [f"# {benchmark.title}", ""]
    lines += [
        f"Produced by `{summary['invocation']}` (preset `{summary['preset']['name']}`: "
        f"{summary['preset']['description']}); total stage time {summary['total_seconds'] / 60:.1f} min.",
        "",
    ]
    provenance = summary.get("provenance") or {}
    if provenance:
        git = provenance["git"]
        revision = (git["revision"] or "unknown")[:12] + (" with uncommitted changes" if git["dirty"] else "")
        lines += [
            f"Code revision {revision}; seed {provenance['seed']}; {threads_line(summary, provenance)} on "
            f"{provenance['machine']['cpu']} (set `SETDIFF_THREADS` to repeat it elsewhere).",
            "",
        ]
    models = summary.get("models") or {}
    for method, model in models.items():
        if "shipped" in model:
            lines.append(
                f"- `{method}`: the shipped model `{model['shipped']}`, trained on "
                f"{', '.join(model['trained_on'])} (none of them a test scene here)."
            )
        else:
            lines.append(f"- `{method}`: trained by this demo ({summary['training_steps'][method]} steps).")
    if models:
        lines.append(f"- Test scenes: {', '.join(summary.get('test_scenes', []))}.")
        lines.append("")
    board = paths.out / f"{benchmark.leaderboard}.md"
    if board.is_file():
        lines += ["## Leaderboard (test scenes)", "", board.read_text(encoding="utf-8").strip(), ""]
        lines += [benchmark.note, ""] if benchmark.note else []
        tolerance = ", ".join(f"{metric.upper()} {value:g}" for metric, value in benchmark.tolerance.items())
        lines += [
            f"On another x86-64 CPU the same command gives the same scenes, fits and packets byte for byte, "
            f"and every cell within {tolerance} of this table (the largest differences measured between CPU "
            f"instruction sets and thread counts, rounded up; docs/reproducibility.md). `setdiff-bench demo` "
            f"prints whether its table is identical to the published one, within that tolerance, or outside it.",
            "",
        ]
    verdict = summary.get(benchmark.verdict_key) or {}
    if verdict.get("means"):
        specs = [get_metric(name) for name in VERDICT_METRICS]
        lines += [
            f"## {benchmark.verdict_title} ({verdict['targets']} targets)",
            "",
            "| method | " + " | ".join(f"{spec.label} {spec.arrow}" for spec in specs) + " |",
            "|---|" + "---:|" * len(specs),
        ]
        for method in METHODS:
            if method in verdict["means"]:
                m = verdict["means"][method]
                lines.append(
                    f"| {method} | "
                    + " | ".join(f"{m[spec.name]:.{spec.decimals}f}" for spec in specs)
                    + " |"
                )
        for other in ("identity", "difix"):
            wins = verdict.get(f"setdiff_beats_{other}")
            if wins:
                said = ", ".join(f"{k.upper()} {'yes' if v else 'no'}" for k, v in wins.items())
                lines.append(f"\nSetDiff beats `{other}` {benchmark.verdict_title.lower()}: {said}.")
        lines.append("")
    lines += refit_section(summary, paths, benchmark.leaderboard)
    for name, title in (
        ("ablation_geometry.md", "Geometry ablation"),
        ("ablation_setsize.md", "Set-size ablation"),
    ):
        if (paths.out / name).is_file():
            lines += [f"- {title}: [{name}]({name})"]
    lines += ["", "## Commands, in order", ""]
    for stage in summary["stages"]:
        timing = f"{stage['seconds']:.0f} s"
        if stage.get("resumed"):
            timing += f", resumed: work done by an earlier run; this run {stage['rerun_seconds']:.0f} s"
        if stage.get("concurrent_group") is not None:
            timing += f", concurrent group {stage['concurrent_group']} lane {stage['lane']}"
        lines.append(f"1. `{stage['command']}` ({stage['name']}, {timing})")
    lines += ["", "## Files", ""]
    lines += [f"- `{name}`" for name in summary["outputs"]]
    lines += [
        "",
        f"Intermediate data (scenes, packets, checkpoints, runs): `{paths.work}` (not versioned).",
        "",
    ]
    return "\n".join(lines)


def refit_section(summary: dict[str, Any], paths: DemoPaths, leaderboard: str) -> list[str]:
    """``demo --refit``: per refitted group the ``X`` / ``X 3D`` / ``X 3D+`` table, the row with the best mean in
    each metric per enhancer and the rows the paired intervals show winning; then links to the refit-steps plot
    and the paired comparisons; ``[]`` for other demos."""
    refit = summary.get("refit") or {}
    verdicts = [v for v in refit.get("groups", []) if v.get("means")]
    if not verdicts:
        return []
    specs = [get_metric(name) for name in VERDICT_METRICS]
    warp = refit.get("warp") or {}
    lines = [
        "## X, X 3D and X 3D+",
        "",
        "`X`: the enhancer on the fit's render; `X-3D`: the render of the fit refitted on `X`'s enhanced novel "
        "views (progressive schedule, docs/refit.md); `X-3D+`: `X` on that render; `identity-3D`: the refit "
        "on un-enhanced renders, the schedule alone. Best mean: the row with the best mean of the group; "
        "paired intervals: the rows no other row beats with a paired interval by scene that excludes 0 "
        "(one row: a winner; several: rows the intervals do not separate)."
        + (
            " warp: mean warp error of the row's camera sequences (all scored groups, MSE on the 0-255 scale)."
            if warp
            else ""
        ),
        "",
    ]
    for verdict in verdicts:
        lines += [
            f"### {verdict['group']} ({verdict['targets']} targets)",
            "",
            "| row | "
            + " | ".join(f"{spec.label} {spec.arrow}" for spec in specs)
            + (" | warp ↓ |" if warp else " |"),
            "|---|" + "---:|" * (len(specs) + bool(warp)),
        ]
        for method in METHODS:
            for name in (method, f"{method}-3D", f"{method}-3D+"):
                if name in verdict["means"]:
                    m = verdict["means"][name]
                    cells = [f"{m[spec.name]:.{spec.decimals}f}" for spec in specs]
                    cells += [f"{warp[name]:.1f}" if name in warp else "–"] if warp else []
                    lines.append(f"| {name} | " + " | ".join(cells) + " |")
        lines.append("")
        winners = verdict.get("winners", {})
        for method, best in verdict.get("best", {}).items():
            said = ", ".join(f"{metric.upper()} `{name}`" for metric, name in best.items())
            line = f"- `{method}`: best mean {said}"
            if method in winners:
                shown = "; ".join(
                    f"{metric.upper()} " + ", ".join(f"`{n}`" for n in names)
                    for metric, names in winners[method].items()
                )
                line += f"; paired intervals: {shown}"
            lines.append(line + ".")
        lines.append("")
    plot = f"{leaderboard}_refit_steps.png"
    if (paths.out / plot).is_file():
        against = "Metrics and warp error" if warp else "Metrics"
        lines.append(f"- {against} against refit steps: [{plot}]({plot}).")
    compares = sorted(p.name for p in paths.out.glob("compare_*.md"))
    if compares:
        lines.append("- Paired gains by scene: " + ", ".join(f"[{n}]({n})" for n in compares) + ".")
    return [*lines, ""]
