"""``fit_gaussians`` and ``fit_scene``: the 3DGS optimisation loop and a scene folder fitted to a PLY (the package's docstring says how)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.fit._checkpoint import (
    STATE_JSON,
    load_checkpoint,
    save_checkpoint,
)
from setdiff_bench.gaussians.fit._config import FitConfig
from setdiff_bench.gaussians.fit._data import FitView
from setdiff_bench.gaussians.fit._init import (
    initial_model,
)
from setdiff_bench.gaussians.fit._trainer import Trainer
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.runtime.devices import resolve_device
from setdiff_bench.types import Scene


@dataclass
class FitResult:
    """What a fit returns: the model, the per-iteration loss and L1, and density-control events."""

    model: GaussianModel
    losses: list[float] = field(default_factory=list)
    l1: list[float] = field(default_factory=list)
    events: list[dict[str, int]] = field(default_factory=list)
    extent: float = 1.0
    start_iteration: int = 1


def fit_gaussians(
    views: Sequence[FitView],
    config: FitConfig,
    *,
    points: np.ndarray | None = None,
    colors: np.ndarray | None = None,
    device: str | torch.device = "cpu",
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_every: int = 0,
    resume: bool = True,
    stop_after: int | None = None,
    progress: bool = True,
    on_iteration: Callable[[int, float], None] | None = None,
) -> FitResult:
    """Fit 3D Gaussians to posed images.

    Args:
        views: training views (images ``(3, H, W)`` in [0, 1], cameras, optional masks).
        config: hyper-parameters and schedule.
        points, colors: ``(P, 3)`` sparse points (world units) and their uint8 colours for initialisation.
        device: ``"cpu"`` (torch rasteriser) or ``"cuda"`` (gsplat).
        checkpoint_dir: where to save/resume the state; ``None`` disables checkpoints.
        checkpoint_every: save every this many iterations (0: only when stopping or finishing).
        resume: continue from a checkpoint in ``checkpoint_dir`` if one exists.
        stop_after: stop (and checkpoint) after this iteration, for interruption tests and time slicing.
        progress: show a tqdm bar.

    Returns:
        :class:`FitResult`; ``losses``/``l1`` cover the iterations run in this call.
    """
    if not views:
        raise UsageError("a fit needs at least one training view")
    if config.iterations < 1:
        raise UsageError(f"iterations must be ≥ 1, got {config.iterations}", "--iterations")
    device = torch.device(resolve_device(str(device)))
    init = initial_model(views, points, colors, config)
    trainer = Trainer(views, init, config, device)
    names = [v.name for v in views]
    folder = Path(checkpoint_dir) if checkpoint_dir is not None else None
    if folder is not None and resume and (folder / STATE_JSON).is_file():
        load_checkpoint(trainer, folder, names)
    result = FitResult(model=init, extent=trainer.extent, start_iteration=trainer.iteration + 1)
    last = config.iterations if stop_after is None else min(config.iterations, stop_after)
    from tqdm.auto import tqdm

    bar = tqdm(
        total=config.iterations,
        initial=trainer.iteration,
        disable=not progress,
        desc="fit",
        unit="it",
        dynamic_ncols=True,
        leave=False,
    )
    try:
        while trainer.iteration < last:
            loss, l1, event = trainer.step()
            result.losses.append(loss)
            result.l1.append(l1)
            if event is not None:
                result.events.append(event)
            if on_iteration is not None:
                on_iteration(trainer.iteration, loss)
            bar.update(1)
            if trainer.iteration % 10 == 0 or trainer.iteration == last:
                bar.set_postfix(loss=f"{loss:.4f}", n=len(trainer.params), refresh=False)
            if folder is not None and checkpoint_every > 0 and trainer.iteration % checkpoint_every == 0:
                save_checkpoint(trainer, folder, names)
    finally:
        bar.close()
    if folder is not None:
        save_checkpoint(trainer, folder, names)
    result.model = trainer.params.model().detach().clone()
    return result


def fit_scene(
    scene_dir: str | os.PathLike[str],
    out_ply: str | os.PathLike[str],
    config: FitConfig,
    *,
    frames: Sequence[str] | None = None,
    device: str | torch.device = "cpu",
    checkpoint_dir: str | os.PathLike[str] | None = None,
    checkpoint_every: int = 0,
    resume: bool = True,
    progress: bool = True,
    dataset: str | None = None,
    scene_name: str | None = None,
    loader_options: dict[str, object] | None = None,
    downscale: int = 1,
    init: str = "auto",
    on_iteration: Callable[[int, float], None] | None = None,
) -> FitResult:
    """Fit a scene folder's training frames (or ``frames``) and write the standard 3DGS PLY to ``out_ply``.

    The scene is read through the loaders (:func:`setdiff_bench.gaussians.fit._data.load_fit_scene`;
    with ``dataset``, ``scene_dir`` is its root and ``scene_name`` the scene); images are undistorted
    and downscaled by ``downscale`` (:func:`~setdiff_bench.gaussians.fit._data.load_fit_views`).  Its
    sparse points, when present, initialise the Gaussians, else points triangulated from the known
    poses (``init``: :func:`setdiff_bench.gaussians.fit._triangulate.initial_points`).  ``on_iteration(iteration,
    loss)`` is called after every optimiser step (progress reports from worker processes).
    """
    from setdiff_bench.gaussians.fit._data import load_fit_scene, load_fit_views, select_fit_frames

    scene = load_fit_scene(scene_dir, dataset=dataset, scene=scene_name, options=loader_options)
    names = select_fit_frames(scene, frames)
    views = load_fit_views(scene, names, downscale=downscale)
    return fit_views_to_ply(
        scene,
        views,
        config,
        out_ply,
        init=init,
        device=device,
        checkpoint_dir=checkpoint_dir,
        checkpoint_every=checkpoint_every,
        resume=resume,
        progress=progress,
        on_iteration=on_iteration,
    )


def fit_views_to_ply(
    scene: Scene,
    views: Sequence[FitView],
    config: FitConfig,
    out_ply: str | os.PathLike[str],
    *,
    init: str = "auto",
    **fit_options: Any,
) -> FitResult:
    """Fit ``views`` of ``scene`` from its initial points (``init``:
    :func:`setdiff_bench.gaussians.fit._triangulate.initial_points`; sparse points, else triangulated from the poses)
    and write the standard 3DGS PLY to ``out_ply``; ``fit_options`` go to :func:`fit_gaussians`."""
    from setdiff_bench.gaussians.fit._triangulate import initial_points
    from setdiff_bench.gaussians.ply import write_ply

    points, colors = initial_points(scene, views, init)
    result = fit_gaussians(views, config, points=points, colors=colors, **fit_options)
    write_ply(out_ply, result.model)
    return result
