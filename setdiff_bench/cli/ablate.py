"""``setdiff-bench ablate geometry|setsize``: the paper's Tables 5 and 6 on a packet store.

    setdiff-bench ablate geometry --packets P --out DIR [--config tiny_setdiff] [--steps N]
    setdiff-bench ablate setsize --packets P --checkpoint CKPT --out DIR [--sizes 1+1,2+1,3+1,3+2,3+4,3+6]

``geometry`` trains four SetDiff variants (no geometry, C-maps only, camera poses only, both) with
the same config, seed and steps, and runs each on the test packets; ``setsize`` runs one trained
SetDiff at several N + M set sizes.  Every stage is an ordinary ``setdiff-bench`` command (listed in
the output tables) and resumes, so an interrupted ablation continues where it stopped.  Tables go to
``<out>/ablation_geometry.{md,tex,parquet}`` and ``<out>/ablation_setsize.{md,tex,parquet}``;
checkpoints and runs to ``--work`` (default ``<out>/work``).
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path
from typing import TYPE_CHECKING

from setdiff_bench.cli import add_device_argument, add_progress_argument

if TYPE_CHECKING:
    from setdiff_bench.pipeline.stages import Pipeline

VERB = "ablate"
HELP = "the paper's ablations: geometric grounding (Table 5) and set size (Table 6)"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="study", metavar="STUDY", required=True)
    geometry = sub.add_parser("geometry", help="train and score SetDiff without / with C-maps / poses / both")
    geometry.add_argument(
        "--config", default="tiny_setdiff", help="base SetDiff config (TOML or packaged name)"
    )
    geometry.add_argument(
        "--steps", type=int, default=None, help="training steps per variant (default: the config's)"
    )
    geometry.add_argument("--seed", type=int, default=None, help="training seed (default: the config's)")
    setsize = sub.add_parser(
        "setsize", help="score one trained SetDiff at several reference + target set sizes"
    )
    setsize.add_argument(
        "--checkpoint", required=True, type=Path, help="trained SetDiff (setdiff-bench train --out)"
    )
    setsize.add_argument("--sizes", default="1+1,2+1,3+1,3+2,3+4,3+6", help="comma list of N+M set sizes")
    for study in (geometry, setsize):
        study.add_argument("--packets", required=True, type=Path, help="packet store (setdiff-bench prepare)")
        study.add_argument("--out", required=True, type=Path, help="folder for the ablation tables")
        study.add_argument(
            "--work", type=Path, default=None, help="checkpoints and runs (default: <out>/work)"
        )
        add_device_argument(study, "where training and inference run")
        add_progress_argument(study)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.pipeline.stages import LEDGER_FILE, Pipeline, StageFailed
    from setdiff_bench.runtime.devices import resolve_device

    resolve_device(
        args.device
    )  # checked here; passed on as given (auto: not at all), so the stages resolve it
    work = (args.work or args.out / "work") / f"ablation_{args.study}"
    pipeline = Pipeline(quiet=args.no_progress, ledger=work / LEDGER_FILE)  # reruns keep the original times
    invocation = _invocation(args)
    try:
        if args.study == "geometry":
            paths = _geometry(args, pipeline, work, invocation)
        else:
            paths = _setsize(args, pipeline, work, invocation)
    except StageFailed as failure:
        return failure.code
    for path in paths.values():
        print(f"wrote {path}")
    return 0


def _invocation(args: argparse.Namespace) -> str:
    """The command line that reproduces this ablation, from the parsed arguments."""
    parts = ["ablate", args.study, "--packets", args.packets, "--out", args.out]
    if args.study == "geometry":
        parts += ["--config", args.config]
        parts += ["--steps", args.steps] if args.steps is not None else []
        parts += ["--seed", args.seed] if args.seed is not None else []
    else:
        parts += ["--checkpoint", args.checkpoint, "--sizes", args.sizes]
    parts += ["--work", args.work] if args.work else []
    parts += ["--device", args.device] if args.device != "auto" else []
    return "setdiff-bench " + shlex.join(str(p) for p in parts)


def _run_args(args: argparse.Namespace) -> list[str]:
    extra = ["--device", args.device] if args.device != "auto" else []
    return [*extra, "--no-progress"] if args.no_progress else extra


def _run_command(
    args: argparse.Namespace, checkpoint: str | Path, out: Path, *options: str
) -> list[str | Path]:
    """The ``run`` verb's arguments for SetDiff (``checkpoint``) on the test split of ``args.packets``, writing
    to ``out``; ``options`` are passed as ``-o`` method options."""
    command: list[str | Path] = ["run", "--method", "setdiff", "--checkpoint", checkpoint]
    command += ["--packets", args.packets, "--split", "test", "--out", out]
    for option in options:
        command += ["-o", option]
    return [*command, *_run_args(args)]


def _geometry(args: argparse.Namespace, pipeline: Pipeline, work: Path, invocation: str) -> dict[str, Path]:
    from setdiff_bench.evaluation.paths import METRICS_FILE
    from setdiff_bench.models.setdiff.config import config_toml_data, write_config_toml
    from setdiff_bench.reporting import ablation

    base = config_toml_data(args.config)
    if base["model"].get("method", "setdiff") != "setdiff":
        from setdiff_bench.errors import UsageError

        raise UsageError('the geometry ablation needs a SetDiff config (method = "setdiff")', args.config)
    results = {}
    for variant in ablation.GEOMETRY_VARIANTS:
        data = {"model": {**base["model"], **variant.overrides}, "train": dict(base["train"])}
        if args.steps is not None:
            data["train"]["steps"] = args.steps
        if args.seed is not None:
            data["train"]["seed"] = args.seed
        config = write_config_toml(
            work / "configs" / f"{variant.key}.toml",
            data,
            f"Geometry ablation variant '{variant.label}' of {args.config}",
        )
        checkpoints = work / "checkpoints" / variant.key
        train = ["train", "--config", config, "--packets", args.packets, "--out", checkpoints]
        if args.device == "cpu":  # train runs where accelerate puts it: CUDA when available unless told cpu
            train += ["--device", "cpu"]
        if args.no_progress:
            train.append("--no-progress")
        pipeline.run(f"train {variant.key}", train)
        runs = work / "runs" / variant.key
        pipeline.run(
            f"run {variant.key}",
            _run_command(args, checkpoints, runs),
        )
        results[variant.key] = ablation.pooled_means(runs / METRICS_FILE)
    frame = ablation.geometry_frame(results)
    caption = "Geometric grounding ablation on the synthetic streets (paper Table 5 shape)"
    commands = f"`{invocation}`, which ran:\n\n" + pipeline.commands_markdown()
    markdown = ablation.geometry_markdown(frame, ablation.ordering_geometry(frame), commands, caption)
    return ablation.write_tables(
        args.out, "ablation_geometry", frame, markdown, ablation.geometry_latex(frame, caption)
    )


def _setsize(args: argparse.Namespace, pipeline: Pipeline, work: Path, invocation: str) -> dict[str, Path]:
    from setdiff_bench.evaluation.paths import METRICS_FILE
    from setdiff_bench.reporting import ablation

    sizes = ablation.parse_sizes(args.sizes)
    results = {}
    for refs, targets in sizes:
        runs = work / "runs" / f"{refs}+{targets}"
        pipeline.run(
            f"run {refs}+{targets}",
            _run_command(args, args.checkpoint, runs, f"max_references={refs}", f"targets_per_set={targets}"),
        )
        results[(refs, targets)] = ablation.pooled_means(runs / METRICS_FILE)
    frame = ablation.setsize_frame(results)
    caption = "Set-size ablation on the synthetic streets (paper Table 6, one row per set size)"
    commands = f"`{invocation}`, which ran:\n\n" + pipeline.commands_markdown()
    targets = int(next(iter(results.values()))["targets"])
    markdown = ablation.setsize_markdown(
        frame, ablation.ordering_setsize(results), commands, caption, targets
    )
    return ablation.write_tables(
        args.out, "ablation_setsize", frame, markdown, ablation.setsize_latex(frame, caption)
    )
