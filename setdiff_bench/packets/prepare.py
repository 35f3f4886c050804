"""``prepare``: a dataset, a protocol and 3DGS fits → a packet store (``setdiff-bench prepare``).

Per scene and group (:mod:`setdiff_bench.packets.plan` for the rules): load or fit the group's
3DGS, render the targets (RGB, C-map, alpha) and the C-maps of the N references chosen by Eq. 2
among the clean fit frames, normalise the packet into its first target's frame at unit extent,
and write it (:mod:`setdiff_bench.packets.store`).

Fits
----
``fits_dir`` (``--fits DIR``): one standard 3DGS PLY per scene and fit key, looked up as
``DIR/<scene>/<fit_key>.ply``, then ``DIR/<scene>/fits/<fit_key>.ply`` (the synthetic generator's
in-scene fits: ``--fits`` may be the dataset root).  ``<scene>`` is the loader's scene name (it may
contain ``/``, e.g. ``Level 1/nuplan_vegas_location_1``); fit keys are the protocol's: EUVS
``level1``/``level2``/``level3``, Para-Lane ``clip_0`` (the training lane), nuScenes ``first_10s``,
DL3DV ``n3``/``n6``/``n9``, synthetic ``lane0``.  The PLY must be in the loader's world frame.
``fit=True`` (``--fit``): fit each one with :func:`setdiff_bench.gaussians.fit.fit_gaussians` on the
group's fit frames (loader resolution, dataset masks), writing ``<out>/fits/<scene>/<fit_key>.ply``
(reused on a rerun; the fit itself checkpoints under ``<fit_key>.ckpt/`` and resumes).

Novel trajectories
------------------
``trajectories`` (``--trajectory shift:3``, repeatable) writes, in place of the protocol's groups, the
packets of each spec and fit: the fit frames' cameras moved along the trajectory are the targets (3DGS
render and C-map, **no ground truth**: null ``gt`` / ``mask`` columns), the references are recorded fit
frames chosen by Eq. 2, the group is the trajectory's label (``shift+3m``) and the split ``test``
(:func:`~setdiff_bench.packets.plan.plan_trajectories`).  Every camera must stay in the scene bounds
(:func:`~setdiff_bench.packets.trajectory.scene_bounds` of the fit); the check runs while planning, before
any packet is written.  Such packets resume, shard and hash like any other; into a store that already
holds the protocol's packets they are added beside them.

Resume, shards, workers
-----------------------
A packet is skipped when its folder holds a fragment with the same recipe and every file matches its
SHA-256.  Work is split into units (scene, fit key), sorted; shard ``i/n`` takes units ``i, i+n, …``,
so shards write disjoint packets and never fit the same model twice.  Each shard merges the fragments
of the whole store into ``index.parquet`` when it ends, without a file lock (see
:func:`~setdiff_bench.packets.index.merge_index`); the last shard to finish publishes the complete index.
On a network filesystem, end with the same command without ``--shard``: it skips every finished packet
and merges.  ``workers`` > 1 renders packets in that many spawned processes.
Packets are byte-identical for identical inputs and render backend, whichever run, shard or worker
wrote them.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import shutil
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from setdiff_bench.errors import DatasetError, ProtocolError, UsageError
from setdiff_bench.gaussians.fit import FitConfig, fit_views_to_ply
from setdiff_bench.gaussians.fit_data import load_fit_views
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.geometry import normalize_packet
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.images import read_mask, read_rgb, to_numpy_hwc
from setdiff_bench.loaders import dataset_spec, list_scenes, load_scenes
from setdiff_bench.loaders.common import select_scenes
from setdiff_bench.packets.index import PACKETS_DIR, group_prefix, merge_index
from setdiff_bench.packets.plan import (
    Crop,
    GroupPlan,
    PacketJob,
    ViewJob,
    applicable_groups,
    plan_recipe_pairs,
    plan_scene,
    plan_trajectories,
)
from setdiff_bench.packets.recipes import PairRecipe, RecipeFrames, parse_pairs, recipe_frames
from setdiff_bench.packets.shards import Shard
from setdiff_bench.packets.store import (
    PacketHeader,
    ViewContent,
    packet_is_complete,
    remove_temporaries,
    write_packet,
)
from setdiff_bench.packets.trajectory import TrajectorySpec, parse_trajectory
from setdiff_bench.protocols import Protocol, load_protocol
from setdiff_bench.runtime.devices import resolve_device
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.types import Frame, Scene, key_fields
from setdiff_bench.undistort import is_distorted, undistort_image, undistortion_maps

SPLIT_CHOICES = ("train", "test", "all")


@dataclass
class PrepareSummary:
    """What a run did.  Times are seconds summed over packets (across workers)."""

    planned: int = 0
    written: int = 0
    skipped: int = 0
    removed: int = 0
    views_written: int = 0
    fits_trained: int = 0
    index_written: bool = False
    wall_s: float = 0.0
    render_s: float = 0.0
    read_s: float = 0.0
    write_s: float = 0.0
    scenes: int = 0
    split_counts: dict[str, int] = field(default_factory=dict)

    def line(self) -> str:
        fits = f"{self.fits_trained} fit(s) trained, " if self.fits_trained else ""
        return (
            f"{fits}{self.planned} packet(s) planned in {self.scenes} scene(s): {self.written} written "
            f"({self.views_written} views), {self.skipped} already complete, {self.removed} outdated removed; "
            f"index {'updated' if self.index_written else 'unchanged'}; {self.wall_s:.1f} s"
        )


@dataclass
class JobStats:
    packet_id: str
    views: int
    render_s: float
    read_s: float
    write_s: float


# ---------------------------------------------------------------------- fits
class FitSource:
    """Finds (or trains) the PLY of each (scene, fit key) and hashes it once."""

    def __init__(
        self,
        *,
        fits_dir: Path | None,
        fit: bool,
        out: Path,
        fit_iterations: int = 30_000,
        fit_config: FitConfig | None = None,
        fit_device: str = "auto",
        progress: bool = True,
        downscale: int = 1,
    ) -> None:
        if (fits_dir is None) == (not fit):
            raise UsageError(
                "give exactly one of --fits DIR (your 3DGS PLYs) or --fit (fit them here)", "--fits"
            )
        self.fits_dir, self.fit, self.out = fits_dir, fit, out
        self.fit_iterations, self.fit_device, self.progress = fit_iterations, fit_device, progress
        self.fit_config = fit_config  # when given: the whole fit configuration (fit_iterations unused)
        self.downscale = downscale  # fit at the protocol's working scale ([images] downscale)
        self.trained = 0
        self._hashes: dict[Path, str] = {}

    def candidates(self, scene: str, fit_key: str) -> list[Path]:
        if self.fit:
            return [self.out / "fits" / scene / f"{fit_key}.ply"]
        assert self.fits_dir is not None
        return [self.fits_dir / scene / f"{fit_key}.ply", self.fits_dir / scene / "fits" / f"{fit_key}.ply"]

    def existing(self, scene: str, fit_key: str) -> Path | None:
        return next((p for p in self.candidates(scene, fit_key) if p.is_file()), None)

    def ensure(
        self, scene: Scene, fit_key: str, fit_frames: Sequence[Frame], *, stop_fraction: float | None = None
    ) -> None:
        """Train the fit if ``--fit`` and it does not exist yet.

        ``stop_fraction`` (the ``underfit`` recipe): run the schedule of the full fit but stop after
        ``max(1, round(stop_fraction × iterations))`` iterations.
        """
        if not self.fit or self.existing(scene.name, fit_key) is not None:
            return

        target = self.candidates(scene.name, fit_key)[0]
        if self.fit_config is not None:
            config = self.fit_config
        elif self.fit_iterations == FitConfig().iterations:
            config = FitConfig()
        else:
            config = FitConfig.schedule(
                self.fit_iterations, densify_every=min(100, max(1, self.fit_iterations // 50))
            )
        device = resolve_device(self.fit_device)
        views = load_fit_views(scene, [f.name for f in fit_frames], downscale=self.downscale)
        stop = None if stop_fraction is None else max(1, round(stop_fraction * config.iterations))
        options = {} if stop is None else {"stop_after": stop}  # only then: full fits are called as before
        fit_views_to_ply(
            scene,
            views,
            config,
            target,
            device=device,
            checkpoint_dir=target.with_suffix(".ckpt"),
            checkpoint_every=1000,
            progress=self.progress,
            **options,
        )
        shutil.rmtree(target.with_suffix(".ckpt"), ignore_errors=True)
        self.trained += 1

    def __call__(self, scene: str, fit_key: str) -> tuple[Path, str]:
        path = self.existing(scene, fit_key)
        if path is None:
            expected = self.candidates(scene, fit_key)[0]
            raise DatasetError(
                f"missing 3DGS fit for scene {scene!r}, fit {fit_key!r} (expected this PLY, or "
                f"{self.candidates(scene, fit_key)[-1].name} under <scene>/fits/; or pass --fit)",
                expected,
            )
        if path not in self._hashes:
            self._hashes[path] = sha256_file(path)
        return path, self._hashes[path]


# ---------------------------------------------------------------------- one packet (worker side)
_MODELS: dict[tuple[Path, int, int, str], Any] = {}
_REFERENCE_RENDERS: OrderedDict[tuple[Any, ...], tuple[torch.Tensor, torch.Tensor]] = OrderedDict()
_REFERENCE_CACHE_SIZE = 64  # views; 64 × (4 × 576 × 1024) float32 ≈ 600 MB at the real datasets' size


def _model(path: Path, device: str) -> Any:
    """The fit at ``path``, cached per process; the key includes the file's size and mtime, so a PLY
    replaced between two in-process ``prepare`` calls is read again instead of rendering the old one."""
    stat = path.stat() if path.is_file() else None
    key = (path, stat.st_size if stat else -1, stat.st_mtime_ns if stat else -1, device)
    if key not in _MODELS:
        _MODELS.clear()  # jobs arrive grouped by fit: keep one model per process
        _REFERENCE_RENDERS.clear()
        _MODELS[key] = read_ply(path).to(device)
    return _MODELS[key]


def _reference_geometry(
    model: Any, references: Sequence[Any], options: dict[str, Any], height: int, width: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """World-frame C-maps ``(N, 3, H, W)`` and alphas ``(N, 1, H, W)`` of the references, cached per process.

    A scene's fit frames serve as references of many packets; their renders do not depend on the
    packet (normalisation is applied afterwards), so each is rendered once per process and model.
    """
    keys = [
        (
            id(model),
            v.frame,
            repr(v.camera.K.tolist()),
            repr(v.camera.w2c.tolist()),
            repr(options["cmap_bound"]),
            repr(tuple(np.asarray(options["cmap_center"]).tolist())),
        )
        for v in references
    ]
    missing = [i for i, key in enumerate(keys) if key not in _REFERENCE_RENDERS]
    if missing:
        out = render(model, [references[i].camera for i in missing], **options)
        for j, i in enumerate(missing):
            _REFERENCE_RENDERS[keys[i]] = (out.cmap[j].float().cpu(), out.alpha[j].float().cpu())
            while len(_REFERENCE_RENDERS) > _REFERENCE_CACHE_SIZE:
                _REFERENCE_RENDERS.popitem(last=False)
    if not references:
        return torch.zeros(0, 3, height, width), torch.zeros(0, 1, height, width)
    for key in keys:
        _REFERENCE_RENDERS.move_to_end(key)
    return (
        torch.stack([_REFERENCE_RENDERS[key][0] for key in keys]),
        torch.stack([_REFERENCE_RENDERS[key][1] for key in keys]),
    )


def resample(
    image: np.ndarray, crop: Crop, resolution: tuple[int, int], *, nearest: bool = False
) -> np.ndarray:
    """Crop ``image`` ``(H, W[, C])`` to ``crop`` and resize to ``resolution`` (H, W) (rules in packets.plan)."""
    window = image[crop.top : crop.top + crop.height, crop.left : crop.left + crop.width]
    out_h, out_w = resolution
    if window.shape[:2] == (out_h, out_w):
        return np.ascontiguousarray(window)
    if nearest:
        interpolation = cv2.INTER_NEAREST
    elif out_h <= window.shape[0] and out_w <= window.shape[1]:
        interpolation = cv2.INTER_AREA
    else:
        interpolation = cv2.INTER_LINEAR
    return cv2.resize(np.ascontiguousarray(window), (out_w, out_h), interpolation=interpolation)


def _capture(view: ViewJob, resolution: tuple[int, int]) -> np.ndarray:
    """The capture of ``view`` at the working resolution, ``(H, W, 3)`` float32 in [0, 1]."""
    assert view.image_path is not None, "a novel-trajectory view has no capture"
    image = resample(read_rgb(view.image_path), view.crop, resolution)
    if is_distorted(view.camera):  # the renderer draws the pinhole camera: resample the capture to it
        image = undistort_image(image, view.camera)[0]
    return np.clip(image, 0.0, 1.0).astype(np.float32)


def _mask(view: ViewJob, resolution: tuple[int, int]) -> np.ndarray:
    covered = (
        undistortion_maps(view.camera)[2] if is_distorted(view.camera) else np.ones(resolution, dtype=bool)
    )
    if view.mask_path is None:
        return covered
    keep = read_mask(view.mask_path)
    if view.invert_mask:
        keep = ~keep
    keep = resample(keep.astype(np.uint8), view.crop, resolution, nearest=True)
    if is_distorted(view.camera):
        keep = (
            undistort_image(keep, view.camera)[0][..., 0]
            if keep.ndim == 3
            else undistort_image(keep, view.camera)[0]
        )
    return keep.astype(bool) & covered


def build_packet(job: PacketJob, root: Path, backend: str, device: str) -> JobStats:
    """Render, normalise and write one packet (runs in a worker process or in-process)."""
    views = (*job.references, *job.targets)
    cameras = [v.camera for v in views]
    start = time.perf_counter()
    model = _model(job.fit_path, device if backend == "torch" else "cuda")
    options = dict(backend=backend, cmap_bound=job.cmap_bound, cmap_center=job.cmap_center)
    with torch.no_grad():
        size = (job.targets[0].camera.height, job.targets[0].camera.width)
        ref_cmap, ref_alpha = _reference_geometry(model, job.references, options, *size)
        out = render(model, [v.camera for v in job.targets], **options)
    rgb = out.rgb.float().cpu()
    cmap = torch.cat([ref_cmap, out.cmap.float().cpu()])
    alpha = torch.cat([ref_alpha, out.alpha.float().cpu()])
    normalised = normalize_packet(cameras, cmap, len(job.references), alphas=alpha)
    rendered = time.perf_counter()
    contents = []
    for i, view in enumerate(views):
        is_target = i >= len(job.references)
        contents.append(
            ViewContent(
                frame=view.frame,
                sensor=view.sensor,
                traversal=view.traversal,
                timestamp_us=view.timestamp_us,
                camera=normalised.cameras[i],
                camera_world=view.camera,
                image=to_numpy_hwc(rgb[i - len(job.references)])
                if is_target
                else _capture(view, job.resolution),
                cmap=to_numpy_hwc(normalised.cmaps[i]),
                alpha=alpha[i, 0].numpy(),
                gt=_capture(view, job.resolution) if is_target and view.image_path is not None else None,
                mask=_mask(view, job.resolution) if is_target and view.image_path is not None else None,
                overlap_score=view.overlap_score,
            )
        )
    read = time.perf_counter()
    header = PacketHeader(
        **key_fields(job),
        fit_key=job.fit_key,
        scale=normalised.scale,
        recipe=job.recipe,
        cmap_half=job.cmap_half,
    )
    n = len(job.references)
    write_packet(root, header, contents[:n], contents[n:])
    done = time.perf_counter()
    return JobStats(job.packet_id, len(views), rendered - start, read - rendered, done - read)


def _init_worker(threads: int) -> None:
    torch.set_num_threads(threads)


# ---------------------------------------------------------------------- orchestration
def declared_split(assignment: Mapping[str, str], test_scenes: Sequence[str]) -> dict[str, str]:
    """The scene split with ``test_scenes`` as the test scenes and every other scene train, in place of the
    protocol's rule (``prepare --test-scene``: a single capture, or a demo that makes only its test scenes).

    Raises:
        UsageError: a named scene is not in the dataset root.
    """
    unknown = sorted(set(test_scenes) - set(assignment))
    if unknown:
        raise UsageError(
            f"no scene {unknown[0]!r} in the dataset root; scenes: {', '.join(sorted(assignment))}",
            "--test-scene",
        )
    return {name: "test" if name in test_scenes else "train" for name in assignment}


def resolve_backend(backend: str, device: str) -> tuple[str, str]:
    """``auto`` → gsplat on CUDA when importable, else the torch backend (on CUDA if present)."""
    device = resolve_device(device)
    if backend == "auto":
        backend = "torch"
        if device.startswith("cuda"):
            try:
                import gsplat  # noqa: F401

                backend = "gsplat"
            except ImportError:
                pass
    if backend not in ("torch", "gsplat"):
        raise UsageError(f"unknown backend {backend!r}; use auto, torch or gsplat", "--backend")
    return backend, device


def prepare(
    dataset: str,
    root: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    protocol: str | os.PathLike[str] | None = None,
    fits: str | os.PathLike[str] | None = None,
    fit: bool = False,
    split: str = "all",
    scenes: Sequence[str] | None = None,
    workers: int = 1,
    shard: Shard = Shard(),
    backend: str = "auto",
    device: str = "auto",
    loader_options: Mapping[str, Any] | None = None,
    fit_iterations: int = 30_000,
    fit_config: FitConfig | None = None,
    threads: int = 1,
    cmap_precision: str = "float32",
    progress: bool = True,
    groups: Sequence[str] | None = None,
    test_scenes: Sequence[str] | None = None,
    trajectories: Sequence[str] | None = None,
    pairs: Sequence[str] | None = None,
) -> PrepareSummary:
    """Prepare the packets of ``dataset`` under ``protocol`` into the store ``out`` (module docstring).

    Args:
        dataset: a loader key (``euvs``, ``paralane``, ``nuscenes``, ``dl3dv``, ``synthetic``).
        root: the dataset root.
        out: the packet store folder (created).
        protocol: packaged protocol name or TOML path; default: the dataset's own.
        fits, fit: user PLYs folder, or fit here (exactly one).
        split: ``train``, ``test`` or ``all`` scenes (the protocol's scene split).
        scenes: restrict to these scene names (the split is still computed over all scenes).
        workers: render processes.  shard: which units this call prepares.
        threads: torch intra-op threads per render process (default 1: the tile rasteriser's ops are
            small, and on a busy machine extra threads slowed a 48×32 render 50× (measured); use
            ``workers`` for parallelism, or more threads for large CPU renders).
        backend, device: renderer (``auto``/``torch``/``gsplat``) and torch device (``auto``/``cpu``/``cuda``).
        loader_options: override the protocol's ``[loader]`` options.
        fit_iterations: 3DGS iterations with ``fit`` (the standard schedule compressed to them).
        fit_config: the whole 3DGS configuration with ``fit``, in place of ``fit_iterations`` (e.g. the fit
            of a synthetic preset, so that degraded recipe fits differ from the scene's own fit only as the
            recipe says).
        cmap_precision: ``"float32"`` (default) or ``"half"`` C-map EXRs (see :mod:`setdiff_bench.packets.store`).
        progress: show tqdm bars.
        groups: only these protocol groups (default all), e.g. ``["holdout8"]`` of a generic capture.
        test_scenes: these scenes are the test scenes and every other one trains, in place of the
            protocol's split rule (:func:`declared_split`).
        trajectories: novel-trajectory specs (``shift:N``, ``yaw:D``, a pose ``.json``;
            :mod:`setdiff_bench.packets.trajectory`): instead of the protocol's groups, write per spec and
            fit the packets whose targets are the fit frames' cameras moved along it, rendered with
            C-maps and without ground truth, references chosen by Eq. 2 among the fit frames
            (:func:`~setdiff_bench.packets.plan.plan_trajectories`; group ``shift+3m``, split ``test``).
            A spec that does not parse, a pose file for several scenes, or a camera leaving the scene
            bounds is refused before anything is written.
        pairs: training-pair recipes (``["sparse:4,underfit:0.5,cross-camera"]``;
            :mod:`setdiff_bench.packets.recipes`): instead of the protocol's groups, write per recipe and
            fit the packets whose targets are recorded frames with their ground truth, rendered from a 3DGS
            degraded as the recipe says (fit key ``<fit_key>@<label>``, trained here with ``fit``), with
            references chosen by Eq. 2 among the recorded frames it saw (group ``sparse4``, the scene's
            split).  An unknown recipe, a parameter out of range, or a recipe a scene cannot follow
            (``cross-camera`` on one camera) is refused before anything is written.

    Raises:
        UsageError / ProtocolError / DatasetError: bad arguments, a protocol that does not fit the
            dataset, missing fits or data.
    """
    dataset_spec(dataset)  # an unknown key is refused with the list of known ones
    specs = parse_trajectories(trajectories or ())
    recipes = parse_pairs(pairs or ())
    if specs and recipes:
        raise UsageError("give --pairs or --trajectory, not both (run prepare once for each)", "--pairs")
    if threads < 1:
        raise UsageError(f"threads must be >= 1, got {threads}", "--threads")
    if cmap_precision not in ("float32", "half"):
        raise UsageError(
            f"cmap precision must be float32 or half, got {cmap_precision!r}", "--cmap-precision"
        )
    with torch_threads(threads):
        return _prepare(
            dataset,
            root,
            out,
            protocol=protocol,
            fits=fits,
            fit=fit,
            split=split,
            scenes=scenes,
            workers=workers,
            shard=shard,
            backend=backend,
            device=device,
            loader_options=loader_options,
            fit_iterations=fit_iterations,
            fit_config=fit_config,
            threads=threads,
            cmap_half=cmap_precision == "half",
            progress=progress,
            groups=groups,
            test_scenes=test_scenes,
            trajectories=specs,
            pairs=recipes,
        )


def parse_trajectories(texts: Sequence[str]) -> tuple[TrajectorySpec, ...]:
    """Parse ``--trajectory`` values (:func:`~setdiff_bench.packets.trajectory.parse_trajectory`).

    Raises:
        UsageError: a spec that does not parse, or two specs with the same label (``shift:3``, ``shift:3.0``).
    """
    specs = tuple(parse_trajectory(text) for text in texts)
    labels = [spec.label for spec in specs]
    twice = sorted({label for label in labels if labels.count(label) > 1})
    if twice:
        raise UsageError(f"trajectory {twice[0]} given twice", "--trajectory")
    return specs


def _prepare(
    dataset: str,
    root: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    protocol: str | os.PathLike[str] | None,
    fits: str | os.PathLike[str] | None,
    fit: bool,
    split: str,
    scenes: Sequence[str] | None,
    workers: int,
    shard: Shard,
    backend: str,
    device: str,
    loader_options: Mapping[str, Any] | None,
    fit_iterations: int,
    threads: int,
    fit_config: FitConfig | None = None,
    cmap_half: bool,
    progress: bool,
    groups: Sequence[str] | None = None,
    test_scenes: Sequence[str] | None = None,
    trajectories: Sequence[TrajectorySpec] = (),
    pairs: Sequence[PairRecipe] = (),
) -> PrepareSummary:
    started = time.perf_counter()
    spec = load_protocol(protocol or dataset)
    if spec.dataset != dataset:
        raise ProtocolError(
            f"protocol {spec.name!r} is for dataset {spec.dataset!r}, not {dataset!r}", spec.path
        )
    if groups:
        known = [g.name for g in spec.groups]
        unknown = [name for name in groups if name not in known]
        if unknown:
            raise UsageError(
                f"protocol {spec.name!r} has no group {unknown[0]!r}; groups: {', '.join(known)}", "--group"
            )
        spec = replace(spec, groups=tuple(g for g in spec.groups if g.name in groups))
    if split not in SPLIT_CHOICES:
        raise UsageError(f"split must be one of {', '.join(SPLIT_CHOICES)}, got {split!r}", "--split")
    if workers < 1:
        raise UsageError(f"workers must be >= 1, got {workers}", "--workers")
    backend, device = resolve_backend(backend, device)
    out = Path(out)
    options = {**spec.loader_options, **(loader_options or {})}
    source = FitSource(
        fits_dir=None if fits is None else Path(fits),
        fit=fit,
        out=out,
        fit_iterations=fit_iterations,
        fit_config=fit_config,
        progress=progress,
        downscale=spec.images.downscale,
    )

    assignment = spec.split.assign(list_scenes(dataset, root, **options))
    if test_scenes is not None:
        assignment = declared_split(assignment, test_scenes)
    chosen = (
        sorted(assignment)
        if scenes is None
        else select_scenes(sorted(assignment), scenes, Path(root), dataset)
    )
    chosen = [name for name in chosen if split == "all" or assignment[name] == split]
    summary = PrepareSummary()
    summary.split_counts = {s: sum(1 for n in chosen if assignment[n] == s) for s in ("train", "test")}
    if len(chosen) > 1 and any(spec.kind == "poses" for spec in trajectories):
        raise UsageError(
            f"a pose file describes one scene's world, and {len(chosen)} scenes are selected; pass --scene",
            "--trajectory",
        )
    loaded = load_scenes(dataset, root, chosen, **options) if chosen else []
    summary.scenes = len(loaded)

    units = _units(spec, loaded)
    mine = shard.select(units)
    jobs: list[PacketJob] = []
    by_name = {s.name: s for s in loaded}
    # every recipe's frames of every unit first: a recipe a scene cannot follow stops before any fit is made
    recipe_plan = _recipe_frames(spec, by_name, mine, pairs)
    for scene_name, fit_key in mine:
        scene = by_name[scene_name]
        groups = [g for g in applicable_groups(spec, scene) if g.fit_key == fit_key]
        fit_frames = [tuple(f.name for f in g.select(scene).fit) for g in groups]
        if len(set(fit_frames)) > 1:
            raise ProtocolError(
                f"groups {', '.join(g.name for g in groups)} share fit_key {fit_key!r} but select "
                f"different fit frames in scene {scene_name!r}",
                spec.path,
            )
        if pairs:
            for _, frames in recipe_plan[(scene_name, fit_key)]:
                if source.fit:
                    source.ensure(
                        scene, f"{fit_key}{frames.fit_suffix}", frames.fit, stop_fraction=frames.stop_fraction
                    )
            plans = plan_recipe_pairs(
                spec,
                scene,
                assignment[scene_name],
                fit_key,
                [g.fit_key for g in applicable_groups(spec, scene)],
                recipe_plan[(scene_name, fit_key)],
                source,
                backend=backend,
                cmap_half=cmap_half,
            )
            summary.removed += _remove_outdated(out, spec, plans)
            jobs += [job for plan in plans for job in plan.jobs]
            continue
        if source.fit:
            source.ensure(scene, fit_key, groups[0].select(scene).fit)
        if trajectories:
            plans = plan_trajectories(
                replace(spec, groups=tuple(groups)),
                scene,
                trajectories,
                source,
                _gaussian_centres(source),
                backend=backend,
                cmap_half=cmap_half,
            )
        else:
            plans = plan_scene(
                replace(spec, groups=tuple(groups)),
                scene,
                assignment[scene_name],
                source,
                backend=backend,
                cmap_half=cmap_half,
            )
        summary.removed += _remove_outdated(out, spec, plans)
        jobs += [job for plan in plans for job in plan.jobs]
    summary.fits_trained = source.trained
    summary.planned = len(jobs)

    todo = []
    for job in jobs:
        remove_temporaries(out, job.packet_id)
        if packet_is_complete(out, job.packet_id, job.recipe):
            summary.skipped += 1
        else:
            todo.append(job)
    for stats in _execute(todo, out, backend, device, workers, threads, progress):
        summary.written += 1
        summary.views_written += stats.views
        summary.render_s += stats.render_s
        summary.read_s += stats.read_s
        summary.write_s += stats.write_s
    summary.index_written = merge_index(out)
    summary.wall_s = time.perf_counter() - started
    return summary


def _recipe_frames(
    protocol: Protocol,
    scenes: Mapping[str, Scene],
    units: Sequence[tuple[str, str]],
    pairs: Sequence[PairRecipe],
) -> dict[tuple[str, str], list[tuple[PairRecipe, RecipeFrames]]]:
    """``(scene, fit key) → [(recipe, its frames)]``: each recipe applied to the unit's recorded frames (the
    fit frames its groups share; :func:`~setdiff_bench.packets.recipes.recipe_frames`).

    Raises:
        UsageError: a recipe the scene cannot follow (raised before anything is fitted or written).
    """
    out: dict[tuple[str, str], list[tuple[PairRecipe, RecipeFrames]]] = {}
    for scene_name, fit_key in units if pairs else ():
        scene = scenes[scene_name]
        group = next(g for g in applicable_groups(protocol, scene) if g.fit_key == fit_key)
        recorded = group.select(scene).fit
        where = f"scene {scene_name!r} (fit {fit_key!r})"
        out[(scene_name, fit_key)] = [(recipe, recipe_frames(recipe, recorded, where)) for recipe in pairs]
    return out


def _gaussian_centres(source: FitSource) -> Callable[[str, str], np.ndarray]:
    """``(scene, fit key) -> (N, 3)`` float32 Gaussian centres of the fit (world frame), for trajectory bounds."""

    def centres(scene: str, fit_key: str) -> np.ndarray:
        path, _ = source(scene, fit_key)
        return read_ply(path).means.detach().cpu().numpy()

    return centres


def _units(protocol: Protocol, scenes: Iterable[Scene]) -> list[tuple[str, str]]:
    """Sorted (scene, fit key) work units (a scene no group applies to is a ``ProtocolError``)."""
    return sorted({(scene.name, g.fit_key) for scene in scenes for g in applicable_groups(protocol, scene)})


def _remove_outdated(root: Path, protocol: Protocol, plans: Sequence[GroupPlan]) -> int:
    """Delete packet folders of these (scene, group)s that the current plan no longer has."""
    folder = root / PACKETS_DIR
    if not folder.is_dir():
        return 0
    removed = 0
    for plan in plans:
        prefix = group_prefix(protocol.name, plan.scene, plan.group)
        keep = {job.packet_id for job in plan.jobs}
        for path in folder.glob(f"{prefix}*"):
            if path.is_dir() and path.name not in keep and path.name[len(prefix) :].isdigit():
                shutil.rmtree(path)
                removed += 1
    return removed


def _execute(
    jobs: Sequence[PacketJob],
    root: Path,
    backend: str,
    device: str,
    workers: int,
    threads: int,
    progress: bool,
) -> Iterable[JobStats]:
    from tqdm.auto import tqdm

    bar = tqdm(
        total=len(jobs),
        desc="prepare",
        unit="packet",
        disable=True if not progress or not jobs else None,
        dynamic_ncols=True,
    )  # None: tqdm hides itself when stderr is not a terminal
    try:
        if workers == 1 or len(jobs) <= 1:
            for job in jobs:
                stats = build_packet(job, root, backend, device)
                bar.update(1)
                yield stats
            return
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(
            max_workers=min(workers, len(jobs)),
            mp_context=context,
            initializer=_init_worker,
            initargs=(threads,),
        ) as pool:
            chunk = math.ceil(len(jobs) / (4 * workers))
            futures = [
                pool.submit(_build_many, jobs[i : i + chunk], root, backend, device)
                for i in range(0, len(jobs), chunk)
            ]
            pending = set(futures)
            try:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_EXCEPTION)
                    for future in done:
                        for stats in future.result():  # re-raises a worker's error here
                            bar.update(1)
                            yield stats
            except BaseException:
                pool.shutdown(wait=True, cancel_futures=True)  # finish running batches, drop queued ones
                raise
    finally:
        bar.close()


def _build_many(jobs: Sequence[PacketJob], root: Path, backend: str, device: str) -> list[JobStats]:
    return [build_packet(job, root, backend, device) for job in jobs]
