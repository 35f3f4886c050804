"""``setdiff-bench ablate geometry|setsize``: the paper's Tables 5 and 6 on a packet store.

    setdiff-bench ablate geometry --packets P --out DIR [--config tiny_setdiff] [--steps N] [--seed S ...]
                                  [--variants none,cmap,pose,both] [--average K] [--guidance-scale G]
    setdiff-bench ablate setsize --packets P --checkpoint CKPT [--checkpoint CKPT ...] --out DIR
                                 [--sizes 1+1,2+1,3+1,3+2,3+4,3+6] [--guidance-scale G]

``geometry`` trains four SetDiff variants (no geometry, C-maps only, camera poses only, both) with
the same config, seed and steps, and runs each on the test packets (``--variants none,both`` keeps the
paper's main comparison at two trainings per seed instead of four); ``setsize`` runs one trained
SetDiff at several N + M set sizes.  Repeating ``--seed`` (geometry: every variant is trained once
per seed) or ``--checkpoint`` (set size: one model per training seed) makes each cell the mean over
the models, with the spread under the table and each model's values in ``*_per_model.parquet``.
``--guidance-scale`` runs every model at that geometry CFG scale instead of its checkpoint's own (an
inference setting, so the trained models are reused; its runs go to ``runs/cfg<G>/``).  ``geometry
--average K`` runs, for every trained variant, the uniform mean of its K newest checkpoints (a ``weights
export --average K`` stage into ``averaged<K>/``; runs in ``runs/avg<K>/``).
Every stage is an ordinary ``setdiff-bench`` command (listed in the output tables) and resumes, so an
interrupted ablation continues where it stopped.  Tables go to ``<out>/ablation_geometry.{md,tex,parquet}``
and ``<out>/ablation_setsize.{md,tex,parquet}``; checkpoints and runs to ``--work`` (default ``<out>/work``).

The examples use the packets of ``setdiff-bench demo --train``, which have the ``train`` split that
``geometry`` needs.  Examples::

    setdiff-bench ablate geometry --packets runs/demo/work/packets --out runs/ablation --variants none,both --steps 200
    setdiff-bench ablate setsize --packets runs/demo/work/packets --checkpoint tiny_setdiff --out runs/ablation \\
        --sizes 1+1,3+1
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


def _with_examples(summary: str, prefix: str) -> str:
    """``summary`` and, under ``Examples:``, the examples of the module docstring that start with ``prefix``
    (a study's own ``--help`` shows its examples, written once)."""
    block = (__doc__ or "").split("Examples", 1)[-1].split("::", 1)[-1]
    examples: list[list[str]] = []
    for line in block.splitlines():
        if line.strip().startswith("setdiff-bench "):
            examples.append([line.rstrip()])
        elif line.strip() and examples and examples[-1][-1].endswith("\\"):
            examples[-1].append(line.rstrip())  # a continued line
    kept = ["\n".join(lines) for lines in examples if lines[0].strip().startswith(prefix)]
    return summary[0].upper() + summary[1:] + "." + ("\n\nExamples:\n\n" + "\n".join(kept) if kept else "")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="study", metavar="STUDY", required=True)
    geometry_help = "train and score SetDiff without / with C-maps / poses / both"
    geometry = sub.add_parser(
        "geometry",
        help=geometry_help,
        description=_with_examples(geometry_help, "setdiff-bench ablate geometry"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    geometry.add_argument(
        "--config", default="tiny_setdiff", help="base SetDiff config (TOML or packaged name)"
    )
    geometry.add_argument(
        "--steps", type=int, default=None, help="training steps per variant (default: the config's)"
    )
    geometry.add_argument(
        "--seed",
        type=int,
        action="append",
        default=None,
        help="training seed (default: the config's); repeat to train every variant once per seed",
    )
    geometry.add_argument(
        "--average",
        type=int,
        metavar="K",
        help="run each variant as the mean of its K newest checkpoints (weights export --average K)",
    )
    geometry.add_argument(
        "--variants",
        default=None,
        help="comma list of the variants to train (default: all four; keys none, cmap, pose, both)",
    )
    setsize_help = "score one trained SetDiff at several reference + target set sizes"
    setsize = sub.add_parser(
        "setsize",
        help=setsize_help,
        description=_with_examples(setsize_help, "setdiff-bench ablate setsize"),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    setsize.add_argument(
        "--checkpoint",
        required=True,
        type=Path,
        action="append",
        help="trained SetDiff (setdiff-bench train --out); repeat for models of other training seeds",
    )
    setsize.add_argument("--sizes", default="1+1,2+1,3+1,3+2,3+4,3+6", help="comma list of N+M set sizes")
    for study in (geometry, setsize):
        study.add_argument("--packets", required=True, type=Path, help="packet store (setdiff-bench prepare)")
        study.add_argument("--out", required=True, type=Path, help="folder for the ablation tables")
        study.add_argument(
            "--work", type=Path, default=None, help="checkpoints and runs (default: <out>/work)"
        )
        study.add_argument(
            "--guidance-scale",
            type=float,
            metavar="G",
            help="geometry CFG scale of every run (default: each checkpoint's own)",
        )
        add_device_argument(study, "where training and inference run")
        add_progress_argument(study)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.models.setdiff.averaging import check_average_count
    from setdiff_bench.models.setdiff.config import check_guidance_scale
    from setdiff_bench.pipeline.stages import LEDGER_FILE, Pipeline, StageFailed
    from setdiff_bench.runtime.devices import resolve_device

    resolve_device(
        args.device
    )  # checked here; passed on as given (auto: not at all), so the stages resolve it
    if args.guidance_scale is not None:
        check_guidance_scale(args.guidance_scale, "--guidance-scale")
    if getattr(args, "average", None) is not None:
        check_average_count(args.average, "--average")
    _check_inputs(args)  # every refusal before the first file is written
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


def _check_inputs(args: argparse.Namespace) -> None:
    """Refuse, before anything is written, what a stage would refuse later: a packet store without the
    splits the study reads, a config or checkpoint that is not SetDiff, unknown variants, and set sizes
    the store's test packets cannot fill (``--sizes 20+1`` on packets of 8 references).

    Raises:
        UsageError, PacketError, CheckpointError: the first problem found, naming its file or option.
    """
    from setdiff_bench.errors import UsageError
    from setdiff_bench.packets.store import PacketStore
    from setdiff_bench.reporting import ablation

    if args.study == "geometry":  # the arguments first, then the files they name
        ablation.parse_variants(args.variants)
    else:
        sizes = ablation.parse_sizes(args.sizes)
    store = PacketStore(args.packets)
    splits = sorted({str(split) for split in store.index["split"]})
    needed = ("train", "test") if args.study == "geometry" else ("test",)
    for split in needed:
        if not store.packet_ids(split):
            raise UsageError(
                f"the {args.study} ablation needs {split} packets; this store has none "
                f"(its splits: {', '.join(splits) or 'none'})",
                args.packets,
            )
    if args.study == "geometry":
        from setdiff_bench.models.setdiff.config_io import config_toml_data

        if config_toml_data(args.config)["model"].get("method", "setdiff") != "setdiff":
            raise UsageError('the geometry ablation needs a SetDiff config (method = "setdiff")', args.config)
        return
    from setdiff_bench.models.setdiff.checkpoint import read_config

    for checkpoint in args.checkpoint:
        method = read_config(checkpoint).model.method
        if method != "setdiff":
            raise UsageError(f"the set-size ablation runs SetDiff; this is a {method} checkpoint", checkpoint)
    rows = store.index[store.index["split"] == "test"]
    counts = rows.groupby(["packet_id", "role"]).size().unstack(fill_value=0)
    fewest_refs = int(counts["ref"].min()) if "ref" in counts else 0
    for refs, targets in sizes:  # fewer targets: a smaller last set
        if refs > fewest_refs:
            raise UsageError(
                f"set size {refs}+{targets} needs {refs} references per packet; the store's test packets "
                f"have as few as {fewest_refs}",
                "--sizes",
            )


def _invocation(args: argparse.Namespace) -> str:
    """The command line that reproduces this ablation, from the parsed arguments."""
    parts = ["ablate", args.study, "--packets", args.packets, "--out", args.out]
    if args.study == "geometry":
        parts += ["--config", args.config]
        parts += ["--steps", args.steps] if args.steps is not None else []
        parts += [part for seed in args.seed or () for part in ("--seed", seed)]
        parts += ["--variants", args.variants] if args.variants is not None else []
        parts += ["--average", args.average] if args.average is not None else []
    else:
        parts += [part for checkpoint in args.checkpoint for part in ("--checkpoint", checkpoint)]
        parts += ["--sizes", args.sizes]
    parts += ["--guidance-scale", f"{args.guidance_scale:g}"] if args.guidance_scale is not None else []
    parts += ["--work", args.work] if args.work else []
    parts += ["--device", args.device] if args.device != "auto" else []
    return "setdiff-bench " + shlex.join(str(p) for p in parts)


def _run_args(args: argparse.Namespace) -> list[str]:
    extra = ["--device", args.device] if args.device != "auto" else []
    return [*extra, "--no-progress"] if args.no_progress else extra


def _runs_folder(args: argparse.Namespace, work: Path) -> Path:
    """Where the run stages write: ``<work>/runs``, or a subfolder naming ``--average`` and
    ``--guidance-scale`` when given (``runs/avg3_cfg1``)."""
    parts = [f"avg{args.average}"] if getattr(args, "average", None) is not None else []
    parts += [f"cfg{args.guidance_scale:g}"] if args.guidance_scale is not None else []
    return work / "runs" / "_".join(parts) if parts else work / "runs"


def _run_command(
    args: argparse.Namespace, checkpoint: str | Path, out: Path, *options: str
) -> list[str | Path]:
    """The ``run`` verb's arguments for SetDiff (``checkpoint``) on the test split of ``args.packets``, writing
    to ``out``; ``options`` are passed as ``-o`` method options, with ``guidance_scale`` when given."""
    command: list[str | Path] = ["run", "--method", "setdiff", "--checkpoint", checkpoint]
    command += ["--packets", args.packets, "--split", "test", "--out", out]
    if args.guidance_scale is not None:
        options = (*options, f"guidance_scale={args.guidance_scale:g}")
    for option in options:
        command += ["-o", option]
    return [*command, *_run_args(args)]


def _store_label(packets: Path) -> str:
    """What the tables' captions call the packet store: its protocols' names (``the synthetic streets`` for the
    driving benchmark's ``synthetic`` protocol, as the captions always said)."""
    from setdiff_bench.packets.store import PacketStore

    protocols = sorted({str(p) for p in PacketStore(packets).index["protocol"].unique()})
    if protocols == ["synthetic"]:
        return "the synthetic streets"
    return "protocol " + ", ".join(protocols)


def _geometry(args: argparse.Namespace, pipeline: Pipeline, work: Path, invocation: str) -> dict[str, Path]:
    from setdiff_bench.io.run_layout import METRICS_FILE
    from setdiff_bench.models.setdiff.config_io import config_toml_data, write_config_toml
    from setdiff_bench.reporting import ablation

    base = config_toml_data(args.config)
    if base["model"].get("method", "setdiff") != "setdiff":
        from setdiff_bench.errors import UsageError

        raise UsageError('the geometry ablation needs a SetDiff config (method = "setdiff")', args.config)
    variants = ablation.parse_variants(args.variants)
    seeds: list[int | None] = list(args.seed or [None])
    per_model: list[dict[str, dict[str, float]]] = []
    for seed in seeds:
        results = {}
        for variant in variants:
            key = variant.key if len(seeds) == 1 else f"{variant.key}_seed{seed}"
            data = {"model": {**base["model"], **variant.overrides}, "train": dict(base["train"])}
            if args.steps is not None:
                data["train"]["steps"] = args.steps
            if seed is not None:
                data["train"]["seed"] = seed
            config = write_config_toml(
                work / "configs" / f"{key}.toml",
                data,
                f"Geometry ablation variant '{variant.label}' of {args.config}",
            )
            checkpoints = work / "checkpoints" / key
            train = ["train", "--config", config, "--packets", args.packets, "--out", checkpoints]
            if args.device == "cpu":  # train runs where accelerate puts it: CUDA when available unless told
                train += ["--device", "cpu"]
            if args.no_progress:
                train.append("--no-progress")
            pipeline.run(f"train {key}", train)
            model = checkpoints
            if args.average is not None:
                averaged = work / f"averaged{args.average}"
                export = ["weights", "export", checkpoints, "--name", key, "--to", averaged]
                pipeline.run(f"average {key}", [*export, "--average", str(args.average)])
                model = averaged / key
            runs = _runs_folder(args, work) / key
            pipeline.run(f"run {key}", _run_command(args, model, runs))
            results[variant.key] = ablation.pooled_means(runs / METRICS_FILE)
        per_model.append(results)
    models = [f"seed {seed}" if seed is not None else f"seed of {args.config}" for seed in seeds]
    labels = {variant.key: variant.label for variant in variants}
    models_results = ablation.ModelResults(per_model, labels, models)
    frame = ablation.geometry_frame(models_results.means())
    caption = f"Geometric grounding ablation on {_store_label(args.packets)} (paper Table 5 shape)"
    commands = f"`{invocation}`, which ran:\n\n" + pipeline.commands_markdown()
    ordering = ablation.ordering_geometry(frame, models_results.per_model)
    markdown = ablation.geometry_markdown(frame, ordering, commands, caption, models_results.spread_notes())
    latex = ablation.geometry_latex(frame, caption)
    return ablation.write_tables(args.out, "ablation_geometry", frame, markdown, latex, models_results)


def _setsize(args: argparse.Namespace, pipeline: Pipeline, work: Path, invocation: str) -> dict[str, Path]:
    from setdiff_bench.io.run_layout import METRICS_FILE
    from setdiff_bench.reporting import ablation

    sizes = ablation.parse_sizes(args.sizes)
    checkpoints: list[Path] = args.checkpoint
    per_model: list[dict[tuple[int, int], dict[str, float]]] = []
    for index, checkpoint in enumerate(checkpoints):
        results = {}
        for refs, targets in sizes:
            key = f"{refs}+{targets}" if len(checkpoints) == 1 else f"model{index}/{refs}+{targets}"
            runs = _runs_folder(args, work) / key
            pipeline.run(
                f"run {key}",
                _run_command(args, checkpoint, runs, f"max_references={refs}", f"targets_per_set={targets}"),
            )
            results[(refs, targets)] = ablation.pooled_means(runs / METRICS_FILE)
        per_model.append(results)
    labels = {size: ablation.size_label(size) for size in sizes}
    models_results = ablation.ModelResults(per_model, labels, [str(checkpoint) for checkpoint in checkpoints])
    means = models_results.means()
    frame = ablation.setsize_frame(means)
    caption = f"Set-size ablation on {_store_label(args.packets)} (paper Table 6, one row per set size)"
    commands = f"`{invocation}`, which ran:\n\n" + pipeline.commands_markdown()
    targets = int(next(iter(means.values()))["targets"])
    ordering = ablation.ordering_setsize(means, models_results.per_model)
    spread = models_results.spread_notes()
    markdown = ablation.setsize_markdown(frame, ordering, commands, caption, targets, spread)
    latex = ablation.setsize_latex(frame, caption)
    return ablation.write_tables(args.out, "ablation_setsize", frame, markdown, latex, models_results)
