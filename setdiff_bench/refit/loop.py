"""The refit's optimisation state and step, and its checkpoints.

:class:`RefitLoop` keeps a 3DGS fit's :class:`~setdiff_bench.gaussians.fit.Trainer` (parameters, Adam
moments, the seeded order of the real views) and the pseudo-views: ``(P, 3, H, W)`` enhanced images on the
8-bit grid and their world cameras.  One step renders one view, real or pseudo as
:meth:`~setdiff_bench.refit.settings.RefitSettings.is_pseudo_step` says, and takes an Adam step on the
photometric loss ``(1 − λ)·L1 + λ·(1 − SSIM)`` of the fit
(:func:`~setdiff_bench.gaussians.fit.photometric_loss`), weighted by ``pseudo_weight`` for a
pseudo-view.  Pseudo-views are visited in a seeded per-epoch permutation drawn from the trainer's generator.

Checkpoints: ``<folder>/step-NNNNNN/`` holds the trainer's fit checkpoint
(:func:`~setdiff_bench.gaussians.fit.save_checkpoint`) and ``refit_state.safetensors`` /
``refit_state.json`` (pseudo-views, their order, the updates done, the refit's identity), and
``<folder>/LATEST`` names the newest complete one; it is rewritten atomically only after the step folder is
complete, so a SIGKILL at any point leaves the previous checkpoint in force.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import CheckpointError
from setdiff_bench.gaussians.fit import Trainer, load_checkpoint, photometric_loss, save_checkpoint
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.atomic import atomic_path, sha256_file, write_text_atomic
from setdiff_bench.refit.settings import RefitSettings

REFIT_STATE_FORMAT = "setdiff-refit-checkpoint/1"
LATEST = "LATEST"
STATE_TENSORS = "refit_state.safetensors"
STATE_JSON = "refit_state.json"


class RefitLoop:
    """The mutable state of one refit (module docstring).

    Args:
        trainer: the fit's trainer, its parameters loaded from the fit (and its checkpoint's Adam moments).
        settings: the schedule.
        identity: what decides the refit's result (inputs and settings); a checkpoint of another is refused.
    """

    def __init__(self, trainer: Trainer, settings: RefitSettings, identity: Mapping[str, Any]) -> None:
        self.trainer = trainer
        self.settings = settings
        self.identity = dict(identity)
        self.pseudo_images = torch.zeros(0, 3, 1, 1)
        self.pseudo_cameras: list[Camera] = []
        self.pseudo_names: list[str] = []
        self.pseudo_order = torch.zeros(0, dtype=torch.int64)
        self.pseudo_position = 0
        self.updates_done = 0

    @property
    def step_count(self) -> int:
        """Refit steps completed."""
        return self.trainer.iteration

    def set_pseudo_views(self, names: Sequence[str], cameras: Sequence[Camera], images: torch.Tensor) -> None:
        """Replace the pseudo-views by ``images`` ``(P, 3, H, W)`` at ``cameras``; a fresh permutation follows."""
        self.pseudo_names = list(names)
        self.pseudo_cameras = list(cameras)
        self.pseudo_images = images.to(self.trainer.device)
        self.pseudo_order = torch.randperm(len(self.pseudo_cameras), generator=self.trainer.generator)
        self.pseudo_position = 0
        self.updates_done += 1

    def _next_pseudo(self) -> int:
        if self.pseudo_position >= len(self.pseudo_order):
            self.pseudo_order = torch.randperm(len(self.pseudo_cameras), generator=self.trainer.generator)
            self.pseudo_position = 0
        index = int(self.pseudo_order[self.pseudo_position])
        self.pseudo_position += 1
        return index

    def step(self) -> tuple[float, bool]:
        """One optimiser step; ``(loss, whether it took a pseudo-view)``."""
        trainer, config = self.trainer, self.trainer.config
        it = trainer.iteration + 1
        pseudo = self.settings.is_pseudo_step(it) and len(self.pseudo_cameras) > 0
        if pseudo:
            index = self._next_pseudo()
            camera, target, mask = self.pseudo_cameras[index], self.pseudo_images[index][None], None
            weight = self.settings.pseudo_weight
        else:
            index = trainer.next_view()
            camera, target, mask = trainer.views[index].camera, trainer.images[index], trainer.masks[index]
            weight = 1.0
        kwargs = {"tile_size": config.tile_size} if trainer.backend == "torch" else {}
        out = render(
            trainer.params.model(),
            [camera],
            trainer.backend,
            with_geometry=False,
            sh_degree=trainer.active_sh,
            background=config.background,
            **kwargs,
        )
        loss, _ = photometric_loss(out.rgb, target, mask, config.lambda_dssim)
        loss = loss * weight
        if loss.requires_grad:  # False only when no Gaussian is visible in the view
            loss.backward()
        with torch.no_grad():
            trainer.params.optimizer.step()
            trainer.params.optimizer.zero_grad(set_to_none=True)
        trainer.iteration = it
        return float(loss.detach()), pseudo

    # ------------------------------------------------------------------ checkpoints
    def save(self, folder: Path) -> None:
        """Write a checkpoint of the current step into ``folder`` (module docstring)."""
        from safetensors.torch import save_file

        name = f"step-{self.step_count:06d}"
        target = folder / name
        if target.exists():
            shutil.rmtree(target)  # a torn attempt at this step, never named by LATEST
        save_checkpoint(self.trainer, target, [v.name for v in self.trainer.views])
        tensors = {
            "pseudo/images": self.pseudo_images.detach().cpu().contiguous(),
            "pseudo/K": torch.from_numpy(
                np.stack([c.K for c in self.pseudo_cameras]) if self.pseudo_cameras else np.zeros((0, 3, 3))
            ),
            "pseudo/w2c": torch.from_numpy(
                np.stack([c.w2c for c in self.pseudo_cameras]) if self.pseudo_cameras else np.zeros((0, 4, 4))
            ),
            "pseudo/order": self.pseudo_order.clone(),
        }
        with atomic_path(target / STATE_TENSORS) as tmp:
            save_file(tensors, str(tmp))
        state = {
            "format": REFIT_STATE_FORMAT,
            "identity": self.identity,
            "steps_done": self.step_count,
            "updates_done": self.updates_done,
            "pseudo_position": self.pseudo_position,
            "pseudo_names": self.pseudo_names,
            "pseudo_sizes": [[c.width, c.height] for c in self.pseudo_cameras],
            "tensors_sha256": sha256_file(target / STATE_TENSORS),
        }
        write_text_atomic(target / STATE_JSON, json.dumps(state, indent=1, sort_keys=True) + "\n")
        write_text_atomic(folder / LATEST, name + "\n")
        for old in folder.glob("step-*"):
            if old.name != name and old.is_dir():
                shutil.rmtree(old)

    def load(self, folder: Path) -> bool:
        """Resume from the newest checkpoint in ``folder``; ``False`` when there is none.

        Raises:
            CheckpointError: a checkpoint of another refit (inputs or settings), or one that is torn or unreadable.
        """
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        pointer = folder / LATEST
        if not pointer.is_file():
            return False
        target = folder / pointer.read_text(encoding="utf-8").strip()
        json_path = target / STATE_JSON
        try:
            state = json.loads(json_path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise CheckpointError(
                f"cannot read refit checkpoint ({exc.__class__.__name__})", json_path
            ) from exc
        if state.get("format") != REFIT_STATE_FORMAT:
            raise CheckpointError(
                f"format is {state.get('format')!r}, expected {REFIT_STATE_FORMAT!r}", json_path
            )
        if state.get("identity") != json.loads(json.dumps(self.identity)):
            raise CheckpointError(
                "the checkpoint is of a refit with other inputs or settings; remove it or choose another --out",
                folder,
            )
        tensor_path = target / STATE_TENSORS
        if not tensor_path.is_file() or sha256_file(tensor_path) != state.get("tensors_sha256"):
            raise CheckpointError("tensor file is missing or does not match refit_state.json", tensor_path)
        try:
            tensors = load_file(str(tensor_path))
        except (SafetensorError, OSError) as exc:
            raise CheckpointError(f"cannot read tensors ({exc})", tensor_path) from exc
        load_checkpoint(self.trainer, target, [v.name for v in self.trainer.views])
        self.pseudo_images = tensors["pseudo/images"].to(self.trainer.device)
        self.pseudo_cameras = [
            Camera(K.numpy(), w2c.numpy(), width, height, source=f"{tensor_path} ({name!r})")
            for K, w2c, (width, height), name in zip(
                tensors["pseudo/K"],
                tensors["pseudo/w2c"],
                state["pseudo_sizes"],
                state["pseudo_names"],
                strict=True,
            )
        ]
        self.pseudo_names = list(state["pseudo_names"])
        self.pseudo_order = tensors["pseudo/order"]
        self.pseudo_position = int(state["pseudo_position"])
        self.updates_done = int(state["updates_done"])
        return True
