"""3D Gaussian Splatting optimisation (Kerbl et al. 2023), the graphdeco-inria training loop on our renderer.

Per iteration: pick the next view of a seeded per-epoch permutation, render it (torch backend on the
CPU, gsplat on CUDA), loss ``(1 − λ)·L1 + λ·(1 − SSIM)`` with λ = 0.2 and the 3DGS SSIM (zero-padded
"same" border, :func:`setdiff_bench.metrics.ssim.ssim`), Adam step with the standard per-parameter
learning rates (position rate × scene extent, decayed exponentially), then adaptive density control
(:mod:`.densify`) and opacity resets on the schedule.  The active SH degree grows by one every
``sh_increase_every`` iterations.  Pixels outside a view's mask (EUVS dynamic masks: 0 = moving
object) take the ground-truth value in the prediction, so they add neither loss nor gradient.

Initialisation (:func:`fit_gaussians`): the given points — for :func:`fit_scene` the scene's sparse
points (COLMAP ``points3D``) when present, else points triangulated from the known poses
(:mod:`setdiff_bench.gaussians.triangulate`) — else :func:`random_init_count` uniform points in the box of the camera centres grown by the scene radius on
every side (colour grey), each as an isotropic Gaussian (nearest-neighbour scale, opacity 0.1).

Checkpoints (``checkpoint_dir``): parameters, Adam moments, density statistics and the random state in
``fit_state.safetensors``; iteration, schedule position, config and view names in ``fit_state.json``
(written last, with the tensor file's SHA-256, so a torn pair is detected).  Resuming restores all
of it, so an interrupted fit ends with exactly the model an uninterrupted one would.  A checkpoint
written before the densification settings moved into ``FitConfig.strategy`` (flat keys) still resumes.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.gaussians.densify import DensificationStrategy, DensityStats
from setdiff_bench.gaussians.fit_data import FitView
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.optim import GaussianParameters, exponential_lr
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.atomic import atomic_path, sha256_file, write_text_atomic
from setdiff_bench.runtime.devices import resolve_device
from setdiff_bench.types import Scene

CHECKPOINT_FORMAT = "setdiff-fit-checkpoint/1"
STATE_TENSORS = "fit_state.safetensors"
STATE_JSON = "fit_state.json"


@dataclass(frozen=True)
class FitConfig:
    """Hyper-parameters; defaults are the Inria 3DGS values for a 30 000-iteration run.

    Learning rates (Adam): ``lr_means`` (× scene extent, decayed to ``lr_means_final`` × extent over
    ``iterations``), ``lr_sh_dc``, ``lr_sh_rest`` (= dc / 20), ``lr_opacity`` (0.05, the original 3DGS
    release and gsplat's default; later Inria versions use 0.025), ``lr_scales``, ``lr_quats``.
    Density control: ``strategy``, a :class:`~setdiff_bench.gaussians.densify.DensificationStrategy`
    that holds its thresholds and schedule (iterations are 1-based as in Inria); it also caps the
    random initialisation at half its ``max_gaussians``.

    ``background_points`` (0 = off, the Inria behaviour) adds that many points on a sphere of
    ``background_radius`` × extent around the cameras, coloured from the training images: SfM leaves
    the sky empty, and a short fit cannot grow Gaussians that far out (street-scene 3DGS methods add a
    similar sky/background initialisation).
    """

    iterations: int = 30_000
    sh_degree: int = 3
    sh_increase_every: int = 1000
    lr_means: float = 1.6e-4
    lr_means_final: float = 1.6e-6
    lr_means_delay_mult: float = 0.01
    lr_sh_dc: float = 2.5e-3
    lr_sh_rest: float = 2.5e-3 / 20
    lr_opacity: float = 0.05
    lr_scales: float = 5e-3
    lr_quats: float = 1e-3
    lambda_dssim: float = 0.2
    strategy: DensificationStrategy = field(default_factory=DensificationStrategy)
    initial_opacity: float = 0.1
    random_init_points: int = 100_000
    background_points: int = 0
    background_radius: float = 30.0
    background: tuple[float, float, float] = (0.0, 0.0, 0.0)
    tile_size: int = 8
    seed: int = 0

    @classmethod
    def schedule(cls, iterations: int, *, densify_every: int, **overrides: object) -> FitConfig:
        """The standard schedule compressed to ``iterations``: raise the SH degree every 10 % of the run,
        and the strategy's (:meth:`DensificationStrategy.schedule`): densify from 10 % to 60 % every
        ``densify_every`` iterations, reset opacities every 30 %.  ``overrides`` name fields of the
        configuration or of its strategy (e.g. ``opacity_reset_every``, ``max_gaussians``)."""
        values, density = split_settings(overrides)
        values = {
            "iterations": iterations,
            "sh_increase_every": max(1, round(0.1 * iterations)),
            **values,
            "strategy": DensificationStrategy.schedule(iterations, densify_every=densify_every, **density),
        }
        return cls(**values)  # type: ignore[arg-type]

    def rescaled(self, iterations: int) -> FitConfig:
        """This configuration run for ``iterations``: every field counted in iterations
        (``sh_increase_every`` and the strategy's :attr:`~DensificationStrategy.SCHEDULE_FIELDS`) scales
        by the same ratio (at least 1); an event this run never reaches (e.g. an opacity reset after the
        last iteration, i.e. disabled) stays unreached; every other setting is kept."""
        ratio = iterations / self.iterations

        def scale(value: int) -> int:
            return iterations + 1 if value > self.iterations else max(1, round(value * ratio))

        names = DensificationStrategy.SCHEDULE_FIELDS
        strategy = dataclasses.replace(self.strategy, **{n: scale(getattr(self.strategy, n)) for n in names})
        return dataclasses.replace(
            self, iterations=iterations, sh_increase_every=scale(self.sh_increase_every), strategy=strategy
        )

    def learning_rates(self, extent: float) -> dict[str, float]:
        return {
            "means": self.lr_means * extent,
            "sh_dc": self.lr_sh_dc,
            "sh_rest": self.lr_sh_rest,
            "opacity_logits": self.lr_opacity,
            "log_scales": self.lr_scales,
            "quats": self.lr_quats,
        }

    def to_json(self) -> dict[str, object]:
        """The configuration as JSON values; the strategy's settings nested under ``"strategy"``."""
        data = dataclasses.asdict(self)
        data["background"] = list(self.background)
        return data

    @classmethod
    def from_json(cls, data: Mapping[str, object]) -> FitConfig:
        """The inverse of :meth:`to_json`; also reads the flat shape written before the strategy object
        (densification settings at the top level).  Missing keys take their defaults.

        Raises:
            UsageError: a key that names no setting, or a ``"strategy"`` that is not an object.
        """
        nested = data.get("strategy", {})
        if not isinstance(nested, Mapping):
            raise UsageError(f"fit configuration: 'strategy' must be an object, got {type(nested).__name__}")
        unknown = sorted(set(nested) - _STRATEGY_FIELDS)
        if unknown:
            raise UsageError(f"fit configuration: the strategy has no setting {unknown[0]!r}")
        values, density = split_settings({k: v for k, v in data.items() if k != "strategy"})
        if "background" in values:
            values["background"] = tuple(values["background"])  # type: ignore[call-overload]
        return cls(**values, strategy=DensificationStrategy(**{**nested, **density}))  # type: ignore[arg-type]


_STRATEGY_FIELDS = frozenset(f.name for f in dataclasses.fields(DensificationStrategy))
_CONFIG_FIELDS = frozenset(f.name for f in dataclasses.fields(FitConfig)) - {"strategy"}


def split_settings(settings: Mapping[str, object]) -> tuple[dict[str, object], dict[str, object]]:
    """``(configuration settings, strategy settings)`` of flat ``settings``, each named by its field.

    Raises:
        UsageError: a name that is a field of neither (one line naming it).
    """
    config: dict[str, object] = {}
    density: dict[str, object] = {}
    for name, value in settings.items():
        if name in _STRATEGY_FIELDS:
            density[name] = value
        elif name in _CONFIG_FIELDS:
            config[name] = value
        else:
            raise UsageError(f"fit configuration has no setting {name!r}")
    return config, density


@dataclass
class FitResult:
    """What a fit returns: the model, the per-iteration loss and L1, and density-control events."""

    model: GaussianModel
    losses: list[float] = field(default_factory=list)
    l1: list[float] = field(default_factory=list)
    events: list[dict[str, int]] = field(default_factory=list)
    extent: float = 1.0
    start_iteration: int = 1


def scene_extent(views: Sequence[FitView]) -> tuple[np.ndarray, float]:
    """Inria ``getNerfppNorm``: centre of the camera centres and 1.1 × the largest distance to it (≥ 1e-3... 1)."""
    centers = np.stack([v.camera.center for v in views])
    center = centers.mean(axis=0)
    radius = float(np.linalg.norm(centers - center, axis=1).max()) * 1.1
    return center, radius if radius > 1e-6 else 1.0


def initial_model(
    views: Sequence[FitView], points: np.ndarray | None, colors: np.ndarray | None, config: FitConfig
) -> GaussianModel:
    """Gaussians at the sparse points, or random ones in the camera box grown by the scene radius; plus
    ``config.background_points`` image-coloured points on a far sphere."""
    if points is not None and len(points) > 0:
        xyz = np.asarray(points, np.float64)
        rgb = None if colors is None else np.asarray(colors)
        if rgb is not None and rgb.dtype != np.uint8:
            rgb = np.rint(np.clip(rgb, 0, 1) * 255).astype(np.uint8)
    else:
        centers = np.stack([v.camera.center for v in views])
        _, radius = scene_extent(views)
        low, high = centers.min(axis=0) - radius, centers.max(axis=0) + radius
        count = random_init_count(views, config)
        generator = torch.Generator().manual_seed(config.seed)
        unit = torch.rand(count, 3, generator=generator, dtype=torch.float64).numpy()
        xyz, rgb = low + unit * (high - low), np.full((count, 3), 128, np.uint8)
    if config.background_points > 0:
        far_xyz, far_rgb = background_sphere(
            views, config.background_points, config.background_radius, config.seed
        )
        xyz, rgb = (
            np.concatenate([xyz, far_xyz]),
            np.concatenate([rgb if rgb is not None else np.full((len(xyz), 3), 128, np.uint8), far_rgb]),
        )
    return GaussianModel.from_points(
        xyz, rgb, sh_degree=config.sh_degree, initial_opacity=config.initial_opacity
    )


def random_init_count(views: Sequence[FitView], config: FitConfig) -> int:
    """Random Gaussians for a scene without sparse points, sized to it: one per 4×4-pixel block of an
    average training view (≥ 1000), at most ``config.random_init_points`` and half the strategy's
    Gaussian cap.
    A 270×480 view gets 8100 instead of the fixed 100 000 that made every step of a short CPU fit
    cost seconds."""
    pixels = float(np.mean([v.camera.width * v.camera.height for v in views]))
    count = min(config.random_init_points, max(1000, round(pixels / 16)))
    cap = config.strategy.max_gaussians
    if cap is not None:
        count = min(count, max(1, cap // 2))
    return count


def background_sphere(
    views: Sequence[FitView], count: int, radius_factor: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points on a Fibonacci sphere of ``radius_factor`` × extent around the camera centres, each
    coloured with the pixel it projects to in the first training view that sees it.  Points below 5° under
    the cameras' horizon (mean camera up = −y axis) and points no view sees are dropped.

    Returns:
        ``xyz (P, 3)`` world units and ``rgb (P, 3)`` uint8.
    """
    center, extent = scene_extent(views)
    k = np.arange(count) + 0.5
    polar = np.arccos(1 - 2 * k / count)
    azimuth = np.pi * (1 + 5**0.5) * k + 2 * np.pi * (seed % 997) / 997
    unit = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], axis=1)
    up = -np.mean([v.camera.R[1] for v in views], axis=0)
    up /= max(float(np.linalg.norm(up)), 1e-12)
    unit = unit[unit @ up > -np.sin(np.radians(5.0))]
    xyz = center + radius_factor * extent * unit
    count = len(xyz)
    rgb = np.zeros((count, 3), np.uint8)
    seen = np.zeros(count, bool)
    for view in views:
        uv, z = view.camera.project(xyz)
        h, w = view.image.shape[1:]
        with np.errstate(invalid="ignore"):
            inside = ~seen & (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        cols, rows = np.floor(uv[inside]).astype(int).T
        rgb[inside] = np.rint(view.image[:, rows, cols].T.numpy() * 255).astype(np.uint8)
        seen |= inside
    return xyz[seen], rgb[seen]


def photometric_loss(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None, lambda_dssim: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(loss, l1)`` for ``(1, 3, H, W)`` images; masked-out pixels take the target value."""
    from setdiff_bench.metrics.ssim import ssim

    if mask is not None:
        pred = torch.where(mask, pred, target)
    l1 = (pred - target).abs().mean()
    d_ssim = 1.0 - ssim(pred, target, border="same").mean()
    return (1.0 - lambda_dssim) * l1 + lambda_dssim * d_ssim, l1


class _Trainer:
    """The mutable state of one fit (kept together so that it can be checkpointed as a whole)."""

    def __init__(
        self, views: Sequence[FitView], init: GaussianModel, config: FitConfig, device: torch.device
    ) -> None:
        self.views = list(views)
        self.config = config
        self.device = device
        self.backend = "gsplat" if device.type == "cuda" else "torch"
        _, self.extent = scene_extent(views)
        self.params = GaussianParameters(init.to(device, torch.float32), config.learning_rates(self.extent))
        self.generator = torch.Generator().manual_seed(config.seed)
        self.density = config.strategy.initialize_state(
            len(self.params), extent=self.extent, generator=self.generator, device=device
        )
        self.order = torch.randperm(len(self.views), generator=self.generator)
        self.position = 0
        self.iteration = 0  # iterations completed
        self.active_sh = 0
        self.images = [v.image.to(device)[None] for v in self.views]
        self.masks = [None if v.mask is None else v.mask.to(device)[None] for v in self.views]

    def next_view(self) -> int:
        if self.position >= len(self.order):
            self.order = torch.randperm(len(self.views), generator=self.generator)
            self.position = 0
        index = int(self.order[self.position])
        self.position += 1
        return index

    def step(self) -> tuple[float, float, dict[str, int] | None]:
        c = self.config
        it = self.iteration + 1
        self.params.set_lr(
            "means",
            exponential_lr(
                it,
                c.lr_means * self.extent,
                c.lr_means_final * self.extent,
                c.iterations,
                delay_mult=c.lr_means_delay_mult,
            ),
        )
        if it % c.sh_increase_every == 0:
            self.active_sh = min(self.active_sh + 1, c.sh_degree)
        index = self.next_view()
        view = self.views[index]
        model = self.params.model()
        kwargs = {"tile_size": c.tile_size} if self.backend == "torch" else {}
        out = render(
            model,
            [view.camera],
            self.backend,
            with_geometry=False,
            sh_degree=self.active_sh,
            background=c.background,
            **kwargs,
        )
        loss, l1 = photometric_loss(out.rgb, self.images[index], self.masks[index], c.lambda_dssim)
        if loss.requires_grad:  # False only when no Gaussian is visible in the view
            loss.backward()
        with torch.no_grad():
            self.params.optimizer.step()
            self.params.optimizer.zero_grad(set_to_none=True)  # parameters only: means2d keeps its .grad
            result = c.strategy.step_post_backward(
                self.params, self.density, it, out.meta[0], view.camera.width, view.camera.height
            )
        event = None if result is None else {"iteration": it, **dataclasses.asdict(result)}
        self.iteration = it
        return float(loss.detach()), float(l1.detach()), event

    # ------------------------------------------------------------------ checkpoints
    def save(self, folder: Path, view_names: Sequence[str]) -> None:
        from safetensors.torch import save_file

        folder.mkdir(parents=True, exist_ok=True)
        tensors = {k: v.detach().cpu().contiguous() for k, v in self.params.state_tensors().items()}
        tensors.update(
            {f"stats/{k}": v.detach().cpu().contiguous() for k, v in self.density.stats.tensors().items()}
        )
        tensors["rng/generator"] = self.generator.get_state().clone()
        tensors["rng/order"] = self.order.clone()
        with atomic_path(folder / STATE_TENSORS) as tmp:
            save_file(tensors, str(tmp))
        state = {
            "format": CHECKPOINT_FORMAT,
            "iteration": self.iteration,
            "position": self.position,
            "active_sh": self.active_sh,
            "extent": self.extent,
            "config": self.config.to_json(),
            "views": list(view_names),
            "tensors_sha256": sha256_file(folder / STATE_TENSORS),
        }
        write_text_atomic(folder / STATE_JSON, json.dumps(state, indent=1, sort_keys=True) + "\n")

    def load(self, folder: Path, view_names: Sequence[str]) -> None:
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        json_path, tensor_path = folder / STATE_JSON, folder / STATE_TENSORS
        try:
            state = json.loads(json_path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise CheckpointError(
                f"cannot read checkpoint state ({exc.__class__.__name__})", json_path
            ) from exc
        if state.get("format") != CHECKPOINT_FORMAT:
            raise CheckpointError(
                f"format is {state.get('format')!r}, expected {CHECKPOINT_FORMAT!r}", json_path
            )
        if saved_config(state, json_path) != self.config:
            raise CheckpointError("checkpoint was written with a different fit configuration", json_path)
        if state.get("views") != list(view_names):
            raise CheckpointError("checkpoint was written for different training frames", json_path)
        if not tensor_path.is_file() or sha256_file(tensor_path) != state.get("tensors_sha256"):
            raise CheckpointError("tensor file is missing or does not match fit_state.json", tensor_path)
        try:
            tensors = load_file(str(tensor_path))
        except (SafetensorError, OSError) as exc:
            raise CheckpointError(f"cannot read tensors ({exc})", tensor_path) from exc
        self.params.load_state_tensors(
            {k: v.to(self.device) for k, v in tensors.items() if k.startswith(("param/", "adam/"))}
        )
        self.density.stats = DensityStats(
            *(tensors[f"stats/{k}"].to(self.device) for k in ("grad_sum", "count", "max_radius"))
        )
        self.generator.set_state(tensors["rng/generator"])
        self.order = tensors["rng/order"]
        self.iteration = int(state["iteration"])
        self.position = int(state["position"])
        self.active_sh = int(state["active_sh"])


def saved_config(state: Mapping[str, object], json_path: Path) -> FitConfig:
    """The configuration a checkpoint's ``fit_state.json`` was written with (either JSON shape)."""
    data = state.get("config")
    if not isinstance(data, Mapping):
        raise CheckpointError("checkpoint holds no fit configuration", json_path)
    try:
        return FitConfig.from_json(data)
    except (UsageError, TypeError, ValueError) as exc:
        raise CheckpointError(f"cannot read the checkpoint's fit configuration ({exc})", json_path) from None


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
    trainer = _Trainer(views, init, config, device)
    names = [v.name for v in views]
    folder = Path(checkpoint_dir) if checkpoint_dir is not None else None
    if folder is not None and resume and (folder / STATE_JSON).is_file():
        trainer.load(folder, names)
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
                trainer.save(folder, names)
    finally:
        bar.close()
    if folder is not None:
        trainer.save(folder, names)
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

    The scene is read through the loaders (:func:`setdiff_bench.gaussians.fit_data.load_fit_scene`;
    with ``dataset``, ``scene_dir`` is its root and ``scene_name`` the scene); images are undistorted
    and downscaled by ``downscale`` (:func:`~setdiff_bench.gaussians.fit_data.load_fit_views`).  Its
    sparse points, when present, initialise the Gaussians, else points triangulated from the known
    poses (``init``: :func:`setdiff_bench.gaussians.triangulate.initial_points`).  ``on_iteration(iteration,
    loss)`` is called after every optimiser step (progress reports from worker processes).
    """
    from setdiff_bench.gaussians.fit_data import load_fit_scene, load_fit_views, select_fit_frames

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
    :func:`setdiff_bench.gaussians.triangulate.initial_points`; sparse points, else triangulated from the poses)
    and write the standard 3DGS PLY to ``out_ply``; ``fit_options`` go to :func:`fit_gaussians`."""
    from setdiff_bench.gaussians.ply import write_ply
    from setdiff_bench.gaussians.triangulate import initial_points

    points, colors = initial_points(scene, views, init)
    result = fit_gaussians(views, config, points=points, colors=colors, **fit_options)
    write_ply(out_ply, result.model)
    return result
