"""``prepare``: a dataset, a protocol and 3DGS fits → a packet store (``setdiff-bench prepare``).

Per scene and group (:mod:`setdiff_bench.packets.plan` for the rules): load or fit the group's
3DGS, render the targets (RGB, C-map, alpha) and the C-maps of the N references chosen by Eq. 2
among the clean fit frames, normalise the packet into its first target's frame at unit extent,
and write it (:mod:`setdiff_bench.packets.store`).

Fits
----
:mod:`setdiff_bench.packets.fits`: ``--fits DIR`` holds one 3DGS PLY per scene and fit key, or ``--fit``
makes them here.  Fit keys are the protocol's: EUVS ``level1``/``level2``/``level3``, Para-Lane
``clip_0``, nuScenes ``first_10s``, DL3DV ``n3``/``n6``/``n9``, synthetic ``lane0``.

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

Modules
-------
Options: :class:`~setdiff_bench.packets.prepare_settings.PrepareSettings`.  Planning:
:mod:`setdiff_bench.packets.plan`.  Fits: :mod:`setdiff_bench.packets.fits`.  One packet:
:mod:`setdiff_bench.packets.worker`; running many: :mod:`setdiff_bench.packets.execute`.  This module
runs a call: scenes, work units, plans, resume, index.
"""

from __future__ import annotations

import os
import shutil
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, get_args

from setdiff_bench.errors import ProtocolError, UsageError
from setdiff_bench.loaders import dataset_spec, list_scenes, load_scenes
from setdiff_bench.loaders.common import select_scenes
from setdiff_bench.packets.execute import execute
from setdiff_bench.packets.fits import FitSource, gaussian_centres
from setdiff_bench.packets.index import PACKETS_DIR, group_prefix, merge_index
from setdiff_bench.packets.jobs import GroupPlan, PacketJob
from setdiff_bench.packets.packing import applicable_groups
from setdiff_bench.packets.plan import plan_scene
from setdiff_bench.packets.plan_pairs import plan_recipe_pairs
from setdiff_bench.packets.plan_trajectories import plan_trajectories
from setdiff_bench.packets.prepare_settings import SPLIT_CHOICES, CmapPrecision, PrepareSettings
from setdiff_bench.packets.recipes import PairRecipe, RecipeFrames, parse_pairs, recipe_frames
from setdiff_bench.packets.trajectory import TrajectorySpec, parse_trajectory
from setdiff_bench.packets.writer import packet_is_complete, remove_temporaries
from setdiff_bench.protocols import Protocol, load_protocol
from setdiff_bench.runtime.devices import resolve_device
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.types import Scene

__all__ = ["PrepareSummary", "declared_split", "parse_trajectories", "prepare", "resolve_backend"]


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
    settings: PrepareSettings | None = None,
    **options: Any,
) -> PrepareSummary:
    """Prepare the packets of ``dataset`` under ``protocol`` into the store ``out`` (module docstring).

    Args:
        dataset: a loader key (``euvs``, ``paralane``, ``nuscenes``, ``dl3dv``, ``synthetic``).
        root: the dataset root.
        out: the packet store folder (created).
        settings: every other option (:class:`~setdiff_bench.packets.prepare_settings.PrepareSettings`:
            protocol, fits / fit, split, scenes, workers, shard, backend, device, loader options, fit
            iterations / configuration, threads, C-map precision, progress, groups, test scenes,
            trajectories, pairs); default: its defaults.
        options: the same options as keywords, over ``settings`` (``prepare(dataset, root, out, fit=True)``).

    Raises:
        UsageError / ProtocolError / DatasetError: bad arguments, a protocol that does not fit the
            dataset, missing fits or data.
    """
    settings = replace(settings or PrepareSettings(), **options)
    dataset_spec(dataset)  # an unknown key is refused with the list of known ones
    specs = parse_trajectories(settings.trajectories or ())
    recipes = parse_pairs(settings.pairs or ())
    if specs and recipes:
        raise UsageError("give --pairs or --trajectory, not both (run prepare once for each)", "--pairs")
    if settings.threads < 1:
        raise UsageError(f"threads must be >= 1, got {settings.threads}", "--threads")
    if settings.cmap_precision not in get_args(CmapPrecision):
        raise UsageError(
            f"cmap precision must be {' or '.join(get_args(CmapPrecision))}, got {settings.cmap_precision!r}",
            "--cmap-precision",
        )
    with torch_threads(settings.threads):
        return _prepare(dataset, root, out, settings, trajectories=specs, pairs=recipes)


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
    settings: PrepareSettings,
    *,
    trajectories: Sequence[TrajectorySpec],
    pairs: Sequence[PairRecipe],
) -> PrepareSummary:
    """:func:`prepare` once its arguments are checked, with ``trajectories`` and ``pairs`` parsed."""
    started = time.perf_counter()
    spec = load_protocol(settings.protocol or dataset)
    if spec.dataset != dataset:
        raise ProtocolError(
            f"protocol {spec.name!r} is for dataset {spec.dataset!r}, not {dataset!r}", spec.path
        )
    if settings.groups:
        known = [g.name for g in spec.groups]
        unknown = [name for name in settings.groups if name not in known]
        if unknown:
            raise UsageError(
                f"protocol {spec.name!r} has no group {unknown[0]!r}; groups: {', '.join(known)}", "--group"
            )
        spec = replace(spec, groups=tuple(g for g in spec.groups if g.name in settings.groups))
    if settings.split not in SPLIT_CHOICES:
        raise UsageError(
            f"split must be one of {', '.join(SPLIT_CHOICES)}, got {settings.split!r}", "--split"
        )
    if settings.workers < 1:
        raise UsageError(f"workers must be >= 1, got {settings.workers}", "--workers")
    backend, device = resolve_backend(settings.backend, settings.device)
    out = Path(out)
    options = {**spec.loader_options, **(settings.loader_options or {})}
    source = FitSource(
        fits_dir=None if settings.fits is None else Path(settings.fits),
        fit=settings.fit,
        out=out,
        fit_iterations=settings.fit_iterations,
        fit_config=settings.fit_config,
        progress=settings.progress,
        downscale=spec.images.downscale,
    )

    assignment = spec.split.assign(list_scenes(dataset, root, **options))
    if settings.test_scenes is not None:
        assignment = declared_split(assignment, settings.test_scenes)
    chosen = (
        sorted(assignment)
        if settings.scenes is None
        else select_scenes(sorted(assignment), settings.scenes, Path(root), dataset)
    )
    chosen = [name for name in chosen if settings.split == "all" or assignment[name] == settings.split]
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
    mine = settings.shard.select(units)
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
                    # cycle: fitted on renders of the scene's own fit, which is made first if missing
                    shift = frames.cycle_shift
                    source.ensure(
                        scene,
                        f"{fit_key}{frames.fit_suffix}",
                        frames.fit,
                        stop_fraction=frames.stop_fraction,
                        cycle=None if shift is None else (fit_key, shift),
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
                cmap_half=settings.cmap_half,
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
                gaussian_centres(source),
                backend=backend,
                cmap_half=settings.cmap_half,
            )
        else:
            plans = plan_scene(
                replace(spec, groups=tuple(groups)),
                scene,
                assignment[scene_name],
                source,
                backend=backend,
                cmap_half=settings.cmap_half,
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
    for stats in execute(todo, out, backend, device, settings.workers, settings.threads, settings.progress):
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
