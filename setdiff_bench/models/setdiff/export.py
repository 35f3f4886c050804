"""``setdiff-bench weights export``: a finished training run's checkpoint (or the average of its last ones) and its
training manifest as a shipped-model folder (:mod:`~setdiff_bench.models.setdiff.packaged`): ``config.json``,
``model.safetensors`` and a ``manifest.json`` whose ``files`` table holds each file's SHA-256.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.io.atomic import sha256_file, staged_folder, write_text_atomic
from setdiff_bench.models.setdiff.averaging import average_weights, check_average_count, run_checkpoints
from setdiff_bench.models.setdiff.checkpoint import read_config, resolve_checkpoint, saved_step, write_weights
from setdiff_bench.models.setdiff.config import Config, check_guidance_scale
from setdiff_bench.models.setdiff.distill import distillation_record
from setdiff_bench.models.setdiff.files import CONFIG_FILE, MANIFEST_FILE, WEIGHTS_FILE
from setdiff_bench.models.setdiff.manifest import read_manifest
from setdiff_bench.models.setdiff.packaged import file_table, packaged_root


def initialisation_record(config: Config) -> dict[str, Any] | None:
    """``{"model", "weights_sha256"}`` of the model a fine-tune started from (``[train] init_from``, as the
    config names it), ``None`` for a model trained from scratch."""
    if config.train.init_from is None:
        return None
    folder = resolve_checkpoint(config.train.init_from)
    return {"model": config.train.init_from, "weights_sha256": sha256_file(folder / WEIGHTS_FILE)}


def export_enhancer(
    checkpoint: Path,
    training_manifest: dict[str, Any],
    destination: Path,
    extra: dict[str, Any] | None = None,
    guidance_scale: float | None = None,
    average: Sequence[Path] = (),
) -> Path:
    """Copy a checkpoint's weights and config into ``destination`` (replaced atomically) with a manifest.

    The manifest of a guidance-distilled student also names its teacher (``distillation``:
    :func:`~setdiff_bench.models.setdiff.distill.distillation_record`), that of a fine-tune the model it
    started from (``initialised_from``: :func:`initialisation_record`).

    Args:
        checkpoint: a checkpoint folder (``config.json`` + ``model.safetensors``).
        training_manifest: the training run's manifest (commands, seed, steps, data, validation).
        destination: the new model folder, e.g. ``<package>/weights/tiny_setdiff``.
        extra: more manifest entries (e.g. the export command, evaluation metrics).
        guidance_scale: when given, the exported config's inference geometry-CFG scale (an inference
            knob, not part of the architecture: the weights are copied unchanged); ``None`` keeps the
            checkpoint's.
        average: when given, checkpoint folders of the same run whose weights' uniform mean is exported
            instead of ``checkpoint``'s (:mod:`~setdiff_bench.models.setdiff.averaging`); the config is
            ``checkpoint``'s.

    Raises:
        CheckpointError: the checkpoint lacks a file.
    """
    names = [CONFIG_FILE, WEIGHTS_FILE]
    for name in names:
        if not (checkpoint / name).is_file():
            raise CheckpointError(f"checkpoint has no {name}", checkpoint)
    saved = read_config(checkpoint)
    teacher = distillation_record(saved)
    origin = initialisation_record(saved)
    config = saved if guidance_scale is not None or average else None
    if config is not None and guidance_scale is not None:
        config = replace(config, model=replace(config.model, guidance_scale=float(guidance_scale)))
    averaged = average_weights(average) if average else None
    with staged_folder(destination) as staging:
        if config is not None and guidance_scale is not None:
            write_text_atomic(staging / CONFIG_FILE, config.to_json() + "\n")
        else:
            shutil.copyfile(checkpoint / CONFIG_FILE, staging / CONFIG_FILE)
        if config is not None and averaged is not None:
            write_weights(staging / WEIGHTS_FILE, averaged, config)
        else:
            shutil.copyfile(checkpoint / WEIGHTS_FILE, staging / WEIGHTS_FILE)
        manifest = {**training_manifest, **(extra or {}), "files": file_table(staging, names)}
        if teacher is not None:  # a guidance-distilled student (:mod:`.distill`)
            manifest["distillation"] = teacher
        if origin is not None:  # a fine-tune of another model
            manifest["initialised_from"] = origin
        write_text_atomic(staging / MANIFEST_FILE, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return destination


def export_run(
    run: Path,
    name: str,
    *,
    to: Path | None = None,
    average: int | None = None,
    guidance_scale: float | None = None,
    force: bool = False,
    command: str | None = None,
) -> tuple[Path, int]:
    """Export a finished training run as the model ``name`` (``weights export``): its newest checkpoint, or the
    uniform mean of its ``average`` newest ones, with its training manifest and an ``export`` record.

    Args:
        run: the training run folder (``setdiff-bench train --out``).
        name: the model's name (letters, digits, ``_``, ``-``).
        to: the folder the model goes into; ``None`` = the package's shipped weights (refused for an existing
            shipped model unless ``force``).
        average, guidance_scale: see :func:`export_enhancer`.
        command: the command line recorded in the manifest.

    Returns:
        The model folder and the checkpoint step exported.

    Raises:
        UsageError: a bad name, scale or count; a shipped model without ``force``; an unfinished run; too few
            kept checkpoints for ``average``.
    """
    if not name.replace("_", "").replace("-", "").isalnum():
        raise UsageError(f"--name must be letters, digits, '_' or '-', got {name!r}", "--name")
    scale = None if guidance_scale is None else check_guidance_scale(guidance_scale, "--guidance-scale")
    if average is not None:
        check_average_count(average, "--average")
    if to is None and (packaged_root() / name).exists() and not force:
        raise UsageError(
            f"{name!r} is a shipped model: exporting would replace it in the package; give --to DIR "
            "to export elsewhere, or --force to replace it",
            "--name",
        )
    checkpoint = resolve_checkpoint(run)
    manifest = read_manifest(run)
    step = saved_step(checkpoint)
    if step != manifest["steps"]:
        raise UsageError(
            f"the run's newest checkpoint is at step {step} of {manifest['steps']}: finish the training first",
            checkpoint,
        )
    averaged: list[tuple[int, Path]] = []
    if average is not None:
        kept = run_checkpoints(run)
        if len(kept) < average or kept[-1][0] != step:
            steps = ", ".join(str(s) for s, _ in kept)
            raise UsageError(
                f"--average {average} needs the run's {average} newest checkpoints up to step {step}; it keeps "
                f"steps {steps}",
                run,
            )
        averaged = kept[-average:]
    destination = (to or packaged_root()) / name
    record: dict[str, Any] = {"command": command, "checkpoint_step": step, "dtype": "float32"}
    if scale is not None:
        record["guidance_scale"] = scale
    if averaged:
        record["averaged_steps"] = [s for s, _ in averaged]
    export_enhancer(
        checkpoint,
        manifest,
        destination,
        extra={"export": record},
        guidance_scale=scale,
        average=[folder for _, folder in averaged],
    )
    return destination, step
