"""Checkpoints: one folder with ``model.safetensors`` (every weight), ``config.json``, and for resuming
training ``optimizer.pt`` (``torch.save`` of the optimizer state, read back with ``weights_only=True``)
and ``trainer.json`` (step count).

Every weight of the model is saved — UNet, VAE (with LoRA and skip convs), Ψ, text embedding — so a
checkpoint is self-contained: loading needs neither the pretrained SD-Turbo folder nor the random
seed.  Folders are written under a temporary name and renamed into place, so a killed process never
leaves a half-written checkpoint.  A training run keeps ``OUT/checkpoints/step-<8-digit step>/`` folders (e.g. ``step-00001500``) and
names the newest one in ``OUT/latest``; any function here taking a checkpoint also accepts ``OUT``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import pickle
import shutil
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import torch

from setdiff_bench.errors import CheckpointError, UsageError, key_mismatch
from setdiff_bench.io.atomic import new_file_mode, staged_folder, write_text_atomic
from setdiff_bench.io.safetensors_header import sort_metadata
from setdiff_bench.io.state_dicts import shapes_of, state_dict_problem
from setdiff_bench.models.setdiff.config import Config, ModelConfig, config_from_dict
from setdiff_bench.models.setdiff.files import (
    CHECKPOINTS_DIR,
    CONFIG_FILE,
    LATEST_FILE,
    OPTIMIZER_FILE,
    TRAINER_FILE,
    WEIGHTS_FILE,
)
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.packaged import packaged_folder, packaged_names


def resolve_checkpoint(path: str | os.PathLike[str]) -> Path:
    """A checkpoint folder, a training output folder's newest checkpoint (via ``OUT/latest``), or the name of
    a shipped model (``tiny_setdiff``, ``tiny_difix``: :mod:`~setdiff_bench.models.setdiff.packaged`)."""
    path = Path(path)
    if not path.exists() and (shipped := packaged_folder(str(path), "enhancer")) is not None:
        return shipped
    if (path / WEIGHTS_FILE).is_file():
        return path
    latest = path / LATEST_FILE
    if latest.is_file():
        candidate = path / latest.read_text(encoding="utf-8").strip()
        if (candidate / WEIGHTS_FILE).is_file():
            return candidate
        raise CheckpointError(f"'latest' names {candidate.name!r}, which has no {WEIGHTS_FILE}", latest)
    if not path.exists():
        known = ", ".join(packaged_names("enhancer")) or "none"
        raise CheckpointError(f"checkpoint not found (shipped models: {known})", path, parameter="checkpoint")
    raise CheckpointError(
        f"not a checkpoint: no {WEIGHTS_FILE} and no '{LATEST_FILE}' file", path, parameter="checkpoint"
    )


def read_config(checkpoint: str | os.PathLike[str]) -> Config:
    """The configuration a checkpoint was saved with."""
    folder = resolve_checkpoint(checkpoint)
    path = folder / CONFIG_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as error:
        raise CheckpointError(f"cannot read checkpoint config: {error}", path) from error
    try:
        return config_from_dict(data, source=str(path))
    except UsageError as error:
        raise CheckpointError(f"invalid checkpoint config: {error.problem}", path) from error


#: Architecture keys named first when they differ: they tell the user most (a DiFix config resumed in a
#: SetDiff run differs in a dozen keys; "method" says why).
_FIRST_REPORTED = ("method", "preset")


#: Architecture keys a model may change from the weights it starts from (``[train] init_from``) or from its
#: teacher (``distill_from``): what the set-mixing layers attend to.  They change no weight's shape; a
#: ``knn`` level adds a "no match" key and value (zeros when the source lacks them).
SET_ATTENTION_KEYS = ("set_attention", "set_attention_neighbours")


def check_compatible(
    saved: Config, expected: Config, where: str | os.PathLike[str], *, ignore: Sequence[str] = ()
) -> None:
    """Raise :class:`CheckpointError` when the two model architectures differ outside ``ignore``, naming one
    differing key: ``method`` or ``preset`` when they differ, else the alphabetically first."""
    a, b = saved.model.architecture(), expected.model.architecture()
    for key in ignore:
        a.pop(key, None)
        b.pop(key, None)
    if a != b:
        rest = sorted((set(a) | set(b)) - set(_FIRST_REPORTED))
        key = next(k for k in (*_FIRST_REPORTED, *rest) if a.get(k) != b.get(k))
        detail = _first_difference(a.get(key), b.get(key))
        raise CheckpointError(f"checkpoint belongs to another configuration: model {key}{detail}", where)


def save_checkpoint(
    folder: str | os.PathLike[str],
    model: torch.nn.Module,
    config: Config,
    *,
    optimizer: torch.optim.Optimizer | None = None,
    step: int | None = None,
) -> Path:
    """Write a checkpoint folder atomically (replacing an existing one of that name).

    Args:
        folder: destination folder.
        model: the (unwrapped) model; every tensor of its ``state_dict`` is saved in float32 or its own dtype.
        config: the full config (model + train), saved as JSON.
        optimizer, step: saved too when given (for resuming training).
    """
    folder = Path(folder)
    model_config = getattr(model, "config", None)
    if isinstance(model_config, ModelConfig):  # the model's resolved choices (e.g. learn_text_embedding)
        config = dataclasses.replace(config, model=model_config)
    with staged_folder(folder) as tmp:
        state = {name: tensor.detach().cpu().contiguous() for name, tensor in model.state_dict().items()}
        write_weights(tmp / WEIGHTS_FILE, state, config)
        (tmp / CONFIG_FILE).write_text(config.to_json() + "\n", encoding="utf-8")
        if optimizer is not None:
            torch.save(optimizer.state_dict(), tmp / OPTIMIZER_FILE)
        if step is not None:
            (tmp / TRAINER_FILE).write_text(json.dumps({"step": int(step)}) + "\n", encoding="utf-8")
    return folder


def write_weights(path: Path, state: dict[str, torch.Tensor], config: Config) -> None:
    """Write a checkpoint's ``model.safetensors`` (the config in its metadata; equal inputs give equal bytes).

    ``path`` should sit in a staged folder: the file is written in place.
    """
    from safetensors.torch import save_file

    save_file(state, str(path), metadata={"format": "setdiff-bench", "config": config.to_json()})
    sort_metadata(path)  # same run, same bytes
    os.chmod(path, new_file_mode())  # safetensors creates it 0600 whatever the umask


def load_weights(
    model: torch.nn.Module,
    checkpoint: str | os.PathLike[str],
    *,
    optional: Callable[[str], bool] | None = None,
) -> None:
    """Load ``model.safetensors`` into ``model`` strictly (every key, every shape).

    ``optional``: keys it accepts may be absent on either side (the model keeps its initial value, or the
    file's tensor is dropped), e.g. :func:`.set_mixer.is_no_match_parameter` when starting a ``knn`` model
    from a ``full`` one.
    """
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    path = resolve_checkpoint(checkpoint) / WEIGHTS_FILE
    try:
        state = load_file(str(path))
    except (OSError, SafetensorError) as error:
        raise CheckpointError(f"cannot read weights: {error}", path) from error
    expected = model.state_dict()
    if optional is not None:
        state = {k: v for k, v in state.items() if k in expected or not optional(k)}
        state |= {k: v for k, v in expected.items() if k not in state and optional(k)}
    problem = state_dict_problem(shapes_of(expected), state)
    if problem is not None and problem.kind == "shape":
        raise CheckpointError(
            f"weight {problem.names[0]} has shape {problem.found}, the model expects {problem.expected}", path
        )
    if problem is not None:
        raise CheckpointError(
            f"weights do not match the model: {key_mismatch(expected, state, examples=2)}", path
        )
    model.load_state_dict(state, strict=True)


def load_model(
    checkpoint: str | os.PathLike[str],
    *,
    expected: Config | None = None,
    ignore: Sequence[str] = (),
    method: str | None = None,
    device: str | torch.device = "cpu",
    dtype: torch.dtype | None = None,
) -> tuple[Any, Config]:
    """Build the model a checkpoint describes and load its weights.

    Args:
        checkpoint: checkpoint folder or training output folder.
        expected: when given, the checkpoint's architecture must equal this config's (outside ``ignore``).
        method: when given (``setdiff``/``difix``), the checkpoint must have been trained as that method.
        device, dtype: where and in which float type to put the model (default float32).

    Returns:
        ``(model in eval mode, saved config)``.
    """
    folder = resolve_checkpoint(checkpoint)
    config = read_config(folder)
    if expected is not None:
        check_compatible(config, expected, folder, ignore=ignore)
    if method is not None and config.model.method != method:
        raise CheckpointError(
            f"checkpoint was trained as method {config.model.method!r}, not {method!r}", folder
        )
    model = SetDiffModel(config.model, load_pretrained=False)
    load_weights(model, folder)
    model.to(device=device, dtype=dtype or torch.float32)
    model.eval()
    return model, config


def load_training_state(checkpoint: Path, optimizer: torch.optim.Optimizer) -> int:
    """Restore the optimizer state of a checkpoint; returns the step it was saved at."""
    trainer_path = checkpoint / TRAINER_FILE
    optimizer_path = checkpoint / OPTIMIZER_FILE
    try:
        step = int(json.loads(trainer_path.read_text(encoding="utf-8"))["step"])
        state = torch.load(optimizer_path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as error:  # weights_only refused a global: anything but plain tensors
        refused = next((line.strip() for line in str(error).splitlines() if "GLOBAL" in line), "")
        raise CheckpointError(
            f"optimizer state refused by torch.load(weights_only=True), it holds more than "
            f"tensors{': ' + refused if refused else ''}",
            optimizer_path,
        ) from None
    except (OSError, KeyError, TypeError, ValueError, EOFError, json.JSONDecodeError, RuntimeError) as error:
        raise CheckpointError(f"cannot resume from this checkpoint: {error}", checkpoint) from error
    try:
        optimizer.load_state_dict(state)
    except (ValueError, KeyError) as error:
        raise CheckpointError(f"optimizer state does not match the model: {error}", optimizer_path) from error
    return step


def saved_step(checkpoint: Path) -> int:
    """The training step a checkpoint folder was saved at (its ``trainer.json``).

    Raises:
        CheckpointError: no readable ``trainer.json``.
    """
    path = checkpoint / TRAINER_FILE
    try:
        return int(json.loads(path.read_text(encoding="utf-8"))["step"])
    except (OSError, KeyError, TypeError, ValueError, json.JSONDecodeError) as error:
        raise CheckpointError(f"cannot read the checkpoint's step: {error}", path) from error


def step_folder(out_dir: Path, step: int) -> Path:
    return out_dir / CHECKPOINTS_DIR / f"step-{step:08d}"


def mark_latest(out_dir: Path, checkpoint: Path, keep: int) -> None:
    """Point ``OUT/latest`` at ``checkpoint`` and delete all but the ``keep`` newest step folders."""
    write_text_atomic(out_dir / LATEST_FILE, checkpoint.relative_to(out_dir).as_posix() + "\n")
    folders = sorted((out_dir / CHECKPOINTS_DIR).glob("step-*"))
    for old in folders[: max(0, len(folders) - max(keep, 1))]:
        if old != checkpoint:
            with contextlib.suppress(OSError):
                shutil.rmtree(old)


def _first_difference(a: Any, b: Any) -> str:
    if isinstance(a, dict) and isinstance(b, dict):
        for key in sorted(set(a) | set(b)):
            if a.get(key) != b.get(key):
                return f".{key} is {a.get(key)!r} in the checkpoint but {b.get(key)!r} in the config"
    return f" is {a!r} in the checkpoint but {b!r} in the config"
