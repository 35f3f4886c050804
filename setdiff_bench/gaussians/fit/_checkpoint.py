"""Checkpoints of a fit: the :class:`~setdiff_bench.gaussians.fit._trainer.Trainer`'s parameters, Adam
moments, density statistics and random state in ``fit_state.safetensors``; iteration, schedule position,
configuration and view names in ``fit_state.json``, written last with the tensor file's SHA-256 so that a
torn pair is detected.  Loading restores all of it, so an interrupted fit ends with exactly the model an
uninterrupted one would.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.gaussians.densify import DensityStats
from setdiff_bench.gaussians.fit._config import FitConfig
from setdiff_bench.gaussians.fit._trainer import Trainer
from setdiff_bench.io.atomic import atomic_path, sha256_file, write_text_atomic

CHECKPOINT_FORMAT = "setdiff-fit-checkpoint/1"
STATE_TENSORS = "fit_state.safetensors"
STATE_JSON = "fit_state.json"


def save_checkpoint(trainer: Trainer, folder: Path, view_names: Sequence[str]) -> None:
    """Write ``trainer``'s state into ``folder`` (the tensor file first, then ``fit_state.json``)."""
    from safetensors.torch import save_file

    folder.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().cpu().contiguous() for k, v in trainer.params.state_tensors().items()}
    tensors.update(
        {f"stats/{k}": v.detach().cpu().contiguous() for k, v in trainer.density.stats.tensors().items()}
    )
    tensors["rng/generator"] = trainer.generator.get_state().clone()
    tensors["rng/order"] = trainer.order.clone()
    with atomic_path(folder / STATE_TENSORS) as tmp:
        save_file(tensors, str(tmp))
    state = {
        "format": CHECKPOINT_FORMAT,
        "iteration": trainer.iteration,
        "position": trainer.position,
        "active_sh": trainer.active_sh,
        "extent": trainer.extent,
        "config": trainer.config.to_json(),
        "views": list(view_names),
        "tensors_sha256": sha256_file(folder / STATE_TENSORS),
    }
    write_text_atomic(folder / STATE_JSON, json.dumps(state, indent=1, sort_keys=True) + "\n")


def load_checkpoint(trainer: Trainer, folder: Path, view_names: Sequence[str]) -> None:
    """Restore ``trainer``'s state from ``folder``; :class:`CheckpointError` when the checkpoint is unreadable,
    torn, or was written with another configuration or other training frames."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    json_path, tensor_path = folder / STATE_JSON, folder / STATE_TENSORS
    try:
        state = json.loads(json_path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise CheckpointError(f"cannot read checkpoint state ({exc.__class__.__name__})", json_path) from exc
    if state.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"format is {state.get('format')!r}, expected {CHECKPOINT_FORMAT!r}", json_path)
    if saved_config(state, json_path) != trainer.config:
        raise CheckpointError("checkpoint was written with a different fit configuration", json_path)
    if state.get("views") != list(view_names):
        raise CheckpointError("checkpoint was written for different training frames", json_path)
    if not tensor_path.is_file() or sha256_file(tensor_path) != state.get("tensors_sha256"):
        raise CheckpointError("tensor file is missing or does not match fit_state.json", tensor_path)
    try:
        tensors = load_file(str(tensor_path))
    except (SafetensorError, OSError) as exc:
        raise CheckpointError(f"cannot read tensors ({exc})", tensor_path) from exc
    trainer.params.load_state_tensors(
        {k: v.to(trainer.device) for k, v in tensors.items() if k.startswith(("param/", "adam/"))}
    )
    trainer.density.stats = DensityStats(
        *(tensors[f"stats/{k}"].to(trainer.device) for k in ("grad_sum", "count", "max_radius"))
    )
    trainer.generator.set_state(tensors["rng/generator"])
    trainer.order = tensors["rng/order"]
    trainer.iteration = int(state["iteration"])
    trainer.position = int(state["position"])
    trainer.active_sh = int(state["active_sh"])


def saved_config(state: Mapping[str, object], json_path: Path) -> FitConfig:
    """The configuration a checkpoint's ``fit_state.json`` was written with (either JSON shape)."""
    data = state.get("config")
    if not isinstance(data, Mapping):
        raise CheckpointError("checkpoint holds no fit configuration", json_path)
    try:
        return FitConfig.from_json(data)
    except (UsageError, TypeError, ValueError) as exc:
        raise CheckpointError(f"cannot read the checkpoint's fit configuration ({exc})", json_path) from None
