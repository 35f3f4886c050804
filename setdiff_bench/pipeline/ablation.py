"""The paper's ablations as a pipeline of CLI stages: geometric grounding (Table 5) and set size (Table 6).

``geometry`` trains SetDiff variants (no geometry, C-maps only, camera poses only, both) with one config,
seed and step count and runs each on the test packets; ``setsize`` runs trained SetDiff checkpoints at
several N + M set sizes.  Every stage is an ordinary ``setdiff-bench`` command run by
:class:`~setdiff_bench.pipeline.stages.Pipeline` (so it resumes and is listed in the tables); the tables
themselves are built by :mod:`setdiff_bench.reporting.ablation`.  ``setdiff-bench ablate`` parses the command
line into :class:`AblationSettings` and calls :func:`run_ablation`.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path

from setdiff_bench.pipeline.stages import LEDGER_FILE, Pipeline

DEFAULT_SIZES = "1+1,2+1,3+1,3+2,3+4,3+6"


@dataclass(frozen=True)
class AblationSettings:
    """One ablation, as ``setdiff-bench ablate`` takes it.

    Attributes:
        study: ``"geometry"`` or ``"setsize"``.
        packets: packet store (``setdiff-bench prepare``); geometry needs its train and test splits.
        out: folder for the tables (``ablation_<study>.{md,tex,parquet}``).
        work: checkpoints and runs (None: ``<out>/work``).
        guidance_scale: geometry CFG scale of every run (None: each checkpoint's own).
        device: ``auto``, ``cpu`` or ``cuda[:N]``, passed on to every stage as given.
        no_progress: stages run with ``--no-progress``.
        config: geometry: base SetDiff config (TOML path or packaged name).
        steps: geometry: training steps per variant (None: the config's).
        seed: geometry: training seeds, each variant trained once per seed (None: the config's).
        average: geometry: run each variant as the mean of its K newest checkpoints.
        variants: geometry: comma list of variant keys (None: all four).
        checkpoint: setsize: trained SetDiff checkpoints, one per training seed.
        sizes: setsize: comma list of N+M set sizes.
    """

    study: str
    packets: Path
    out: Path
    work: Path | None = None
    guidance_scale: float | None = None
    device: str = "auto"
    no_progress: bool = False
    config: str = "tiny_setdiff"
    steps: int | None = None
    seed: tuple[int, ...] | None = None
    average: int | None = None
    variants: str | None = None
    checkpoint: tuple[Path, ...] = ()
    sizes: str = DEFAULT_SIZES


def run_ablation(settings: AblationSettings) -> dict[str, Path]:
    """Check the inputs, run every stage of the study (resuming what an earlier run finished) and write its
    tables.

    Returns:
        The written tables by kind (``markdown``, ``latex``, ``parquet``, ...).

    Raises:
        UsageError, PacketError, CheckpointError: an input refused before the first file is written.
        StageFailed: a stage exited non-zero (its own one-line error already printed).
    """
    check_ablation_inputs(settings)  # every refusal before the first file is written
    work = (settings.work or settings.out / "work") / f"ablation_{settings.study}"
    pipeline = Pipeline(
        quiet=settings.no_progress, ledger=work / LEDGER_FILE
    )  # reruns keep the original times
    invocation = ablation_command(settings)
    if settings.study == "geometry":
        return _geometry(settings, pipeline, work, invocation)
    return _setsize(settings, pipeline, work, invocation)


def check_ablation_inputs(settings: AblationSettings) -> None:
    """Refuse, before anything is written, what a stage would refuse later: a packet store without the
    splits the study reads, a config or checkpoint that is not SetDiff, unknown variants, and set sizes
    the store's test packets cannot fill (``--sizes 20+1`` on packets of 8 references).

    Raises:
        UsageError, PacketError, CheckpointError: the first problem found, naming its file or option.
    """
    from setdiff_bench.errors import UsageError
    from setdiff_bench.packets.store import PacketStore
    from setdiff_bench.reporting import ablation

    if settings.study == "geometry":  # the arguments first, then the files they name
        ablation.parse_variants(settings.variants)
    else:
        sizes = ablation.parse_sizes(settings.sizes)
    store = PacketStore(settings.packets)
    splits = sorted({str(split) for split in store.index["split"]})
    needed = ("train", "test") if settings.study == "geometry" else ("test",)
    for split in needed:
        if not store.packet_ids(split):
            raise UsageError(
                f"the {settings.study} ablation needs {split} packets; this store has none "
                f"(its splits: {', '.join(splits) or 'none'})",
                settings.packets,
            )
    if settings.study == "geometry":
        from setdiff_bench.models.setdiff.config_io import config_toml_data

        if config_toml_data(settings.config)["model"].get("method", "setdiff") != "setdiff":
            raise UsageError(
                'the geometry ablation needs a SetDiff config (method = "setdiff")', settings.config
            )
        return
    from setdiff_bench.models.setdiff.checkpoint import read_config

    for checkpoint in settings.checkpoint:
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


def ablation_command(settings: AblationSettings) -> str:
    """The command line that reproduces this ablation, from the parsed arguments."""
    parts = ["ablate", settings.study, "--packets", settings.packets, "--out", settings.out]
    if settings.study == "geometry":
        parts += ["--config", settings.config]
        parts += ["--steps", settings.steps] if settings.steps is not None else []
        parts += [part for seed in settings.seed or () for part in ("--seed", seed)]
        parts += ["--variants", settings.variants] if settings.variants is not None else []
        parts += ["--average", settings.average] if settings.average is not None else []
    else:
        parts += [part for checkpoint in settings.checkpoint for part in ("--checkpoint", checkpoint)]
        parts += ["--sizes", settings.sizes]
    parts += (
        ["--guidance-scale", f"{settings.guidance_scale:g}"] if settings.guidance_scale is not None else []
    )
    parts += ["--work", settings.work] if settings.work else []
    parts += ["--device", settings.device] if settings.device != "auto" else []
    return "setdiff-bench " + shlex.join(str(p) for p in parts)


def _run_args(settings: AblationSettings) -> list[str]:
    extra = ["--device", settings.device] if settings.device != "auto" else []
    return [*extra, "--no-progress"] if settings.no_progress else extra


def _runs_folder(settings: AblationSettings, work: Path) -> Path:
    """Where the run stages write: ``<work>/runs``, or a subfolder naming ``--average`` and
    ``--guidance-scale`` when given (``runs/avg3_cfg1``)."""
    parts = [f"avg{settings.average}"] if settings.average is not None else []
    parts += [f"cfg{settings.guidance_scale:g}"] if settings.guidance_scale is not None else []
    return work / "runs" / "_".join(parts) if parts else work / "runs"


def _run_command(
    settings: AblationSettings, checkpoint: str | Path, out: Path, *options: str
) -> list[str | Path]:
    """The ``run`` verb's arguments for SetDiff (``checkpoint``) on the test split of ``settings.packets``, writing
    to ``out``; ``options`` are passed as ``-o`` method options, with ``guidance_scale`` when given."""
    command: list[str | Path] = ["run", "--method", "setdiff", "--checkpoint", checkpoint]
    command += ["--packets", settings.packets, "--split", "test", "--out", out]
    if settings.guidance_scale is not None:
        options = (*options, f"guidance_scale={settings.guidance_scale:g}")
    for option in options:
        command += ["-o", option]
    return [*command, *_run_args(settings)]


def _store_label(packets: Path) -> str:
    """What the tables' captions call the packet store: its protocols' names (``the synthetic streets`` for the
    driving benchmark's ``synthetic`` protocol, as the captions always said)."""
    from setdiff_bench.packets.store import PacketStore

    protocols = sorted({str(p) for p in PacketStore(packets).index["protocol"].unique()})
    if protocols == ["synthetic"]:
        return "the synthetic streets"
    return "protocol " + ", ".join(protocols)


def _geometry(settings: AblationSettings, pipeline: Pipeline, work: Path, invocation: str) -> dict[str, Path]:
    from setdiff_bench.io.run_layout import METRICS_FILE
    from setdiff_bench.models.setdiff.config_io import config_toml_data, write_config_toml
    from setdiff_bench.reporting import ablation

    base = config_toml_data(settings.config)  # a SetDiff config: check_ablation_inputs refused any other
    variants = ablation.parse_variants(settings.variants)
    seeds: list[int | None] = list(settings.seed or [None])
    per_model: list[dict[str, dict[str, float]]] = []
    for seed in seeds:
        results = {}
        for variant in variants:
            key = variant.key if len(seeds) == 1 else f"{variant.key}_seed{seed}"
            data = {"model": {**base["model"], **variant.overrides}, "train": dict(base["train"])}
            if settings.steps is not None:
                data["train"]["steps"] = settings.steps
            if seed is not None:
                data["train"]["seed"] = seed
            config = write_config_toml(
                work / "configs" / f"{key}.toml",
                data,
                f"Geometry ablation variant '{variant.label}' of {settings.config}",
            )
            checkpoints = work / "checkpoints" / key
            train = ["train", "--config", config, "--packets", settings.packets, "--out", checkpoints]
            if (
                settings.device == "cpu"
            ):  # train runs where accelerate puts it: CUDA when available unless told
                train += ["--device", "cpu"]
            if settings.no_progress:
                train.append("--no-progress")
            pipeline.run(f"train {key}", train)
            model = checkpoints
            if settings.average is not None:
                averaged = work / f"averaged{settings.average}"
                export = ["weights", "export", checkpoints, "--name", key, "--to", averaged]
                pipeline.run(f"average {key}", [*export, "--average", str(settings.average)])
                model = averaged / key
            runs = _runs_folder(settings, work) / key
            pipeline.run(f"run {key}", _run_command(settings, model, runs))
            results[variant.key] = ablation.pooled_means(runs / METRICS_FILE)
        per_model.append(results)
    models = [f"seed {seed}" if seed is not None else f"seed of {settings.config}" for seed in seeds]
    labels = {variant.key: variant.label for variant in variants}
    models_results = ablation.ModelResults(per_model, labels, models)
    frame = ablation.geometry_frame(models_results.means())
    caption = f"Geometric grounding ablation on {_store_label(settings.packets)} (paper Table 5 shape)"
    commands = f"`{invocation}`, which ran:\n\n" + pipeline.commands_markdown()
    ordering = ablation.ordering_geometry(frame, models_results.per_model)
    markdown = ablation.geometry_markdown(frame, ordering, commands, caption, models_results.spread_notes())
    latex = ablation.geometry_latex(frame, caption)
    return ablation.write_tables(settings.out, "ablation_geometry", frame, markdown, latex, models_results)


def _setsize(settings: AblationSettings, pipeline: Pipeline, work: Path, invocation: str) -> dict[str, Path]:
    from setdiff_bench.io.run_layout import METRICS_FILE
    from setdiff_bench.reporting import ablation

    sizes = ablation.parse_sizes(settings.sizes)
    checkpoints = list(settings.checkpoint)
    per_model: list[dict[tuple[int, int], dict[str, float]]] = []
    for index, checkpoint in enumerate(checkpoints):
        results = {}
        for refs, targets in sizes:
            key = f"{refs}+{targets}" if len(checkpoints) == 1 else f"model{index}/{refs}+{targets}"
            runs = _runs_folder(settings, work) / key
            pipeline.run(
                f"run {key}",
                _run_command(
                    settings, checkpoint, runs, f"max_references={refs}", f"targets_per_set={targets}"
                ),
            )
            results[(refs, targets)] = ablation.pooled_means(runs / METRICS_FILE)
        per_model.append(results)
    labels = {size: ablation.size_label(size) for size in sizes}
    models_results = ablation.ModelResults(per_model, labels, [str(checkpoint) for checkpoint in checkpoints])
    means = models_results.means()
    frame = ablation.setsize_frame(means)
    caption = f"Set-size ablation on {_store_label(settings.packets)} (paper Table 6, one row per set size)"
    commands = f"`{invocation}`, which ran:\n\n" + pipeline.commands_markdown()
    targets = int(next(iter(means.values()))["targets"])
    ordering = ablation.ordering_setsize(means, models_results.per_model)
    spread = models_results.spread_notes()
    markdown = ablation.setsize_markdown(frame, ordering, commands, caption, targets, spread)
    latex = ablation.setsize_latex(frame, caption)
    return ablation.write_tables(settings.out, "ablation_setsize", frame, markdown, latex, models_results)
