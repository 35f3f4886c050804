"""One scene's refit, end to end: inputs → checked fit → refit loop with enhancer updates → PLY + manifest.

What is read, in order (nothing is written before every input is checked):

1. the protocol and the scene through the dataset loaders, as ``prepare`` reads them;
2. the targets: a protocol group's packets (:func:`setdiff_bench.packets.plan.plan_scene`) or a novel
   trajectory's (:func:`~setdiff_bench.packets.plan.plan_trajectories`), planned exactly as ``prepare`` plans
   them (same chunks, same Eq. 2 references).  Only their cameras and names are kept
   (:func:`~setdiff_bench.refit.packets.target_view`): ground truth of a target never reaches the refit;
3. the fit: ``fits`` (``DIR/<scene>/<fit_key>.ply`` as ``prepare --fits``) or fitted here from scratch
   (``fit_iterations``; :class:`~setdiff_bench.packets.fits.FitSource`), optionally its fit checkpoint
   (Adam moments; it must hold the PLY's Gaussians); the fit must render its training views at
   detail correlation ``min_fit_correlation`` or better (a PLY of another scene is refused) and every target camera must lie in the
   scene bounds (:func:`~setdiff_bench.packets.trajectory.check_within_bounds`);
4. the enhancer (:func:`setdiff_bench.enhancers.base.create_enhancer`) and its weights' fingerprint.

Then :class:`~setdiff_bench.refit.loop.RefitLoop` runs ``steps`` steps; before each update step
(:meth:`~setdiff_bench.refit.settings.RefitSettings.update_steps`) the pseudo-views are rebuilt: each target's
camera ``min(1, k · pose_fraction)`` of the way from its nearest training pose, references re-chosen by Eq. 2
for those cameras among the fit frames (the packet's own references once at the target), a packet of the
current model's renders (:func:`~setdiff_bench.refit.packets.current_packet`), ``enhancer.enhance(packet)``
checked for shape (:func:`~setdiff_bench.evaluation.packet_scoring.check_output`) and put on the 8-bit grid.

Output in ``out`` (:func:`refit_paths`): ``<scene>/<fit_key>.ply`` (so that ``prepare --fits OUT`` renders the
refit scene; several scenes' refits share one ``out``) and ``<scene>/<fit_key>.refit.json`` (the manifest,
written last), both atomically; ``<scene>/<fit_key>.refit-checkpoint/`` while it runs (removed at the end).  A rerun resumes from the checkpoint and ends with the same bytes; a finished ``out`` is left as it is.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from setdiff_bench.errors import CheckpointError, PlyError, UsageError
from setdiff_bench.io.refit_layout import REFIT_FORMAT, refit_paths, snapshot_folder
from setdiff_bench.refit.settings import RefitSettings


@dataclass(frozen=True)
class RefitTask:
    """What to refit and with which enhancer.

    Attributes:
        dataset, root, scene: the scene as ``prepare`` reads it (loader key, dataset root, scene name).
        out: the output folder.
        method, method_options: the enhancer (``setdiff-bench list methods``) and its options
            (``checkpoint``, ``source``, ...).
        group: the protocol group whose targets are distilled (e.g. ``lane+2``); with ``trajectory``, the group
            whose fit frames are walked (default: the scene's only fit).
        trajectory: a novel trajectory (``shift:3``, ``yaw:10``, a pose ``.json``) instead of the group's targets.
        protocol: packaged protocol name or TOML path (default: the dataset's own).
        loader_options: override the protocol's ``[loader]`` options, as ``prepare -o`` does (e.g.
            ``{"missing": "skip"}`` for a ``transforms.json`` that lists frames without a photo).
        test_scenes: declare these scenes the test scenes (every other one train) in place of the protocol's
            scene split, as ``prepare --test-scene`` does: the scene's split chooses its packets' shape and
            reference count (the protocol's ``[references]`` train / test), so a refit must use the split of the
            packets it is scored on.
        fits: folder of fit PLYs (``DIR/<scene>/<fit_key>.ply``); or ``fit_iterations`` to fit here.
        fit_checkpoint: the fit's checkpoint folder (``fit --checkpoint``), for its Adam moments.
        device, backend: torch device and renderer (``auto``: as ``prepare``).
    """

    dataset: str
    root: Path
    scene: str
    out: Path
    method: str
    method_options: Mapping[str, Any] = field(default_factory=dict)
    group: str | None = None
    trajectory: str | None = None
    protocol: str | None = None
    loader_options: Mapping[str, Any] = field(default_factory=dict)
    test_scenes: tuple[str, ...] | None = None
    fits: Path | None = None
    fit_iterations: int | None = None
    fit_checkpoint: Path | None = None
    device: str = "auto"
    backend: str = "auto"


@dataclass
class RefitResult:
    """What :func:`refit_scene` did: the PLY, the manifest (its file and content), and whether it resumed or
    found the work done."""

    ply: Path
    manifest_path: Path
    manifest: dict[str, Any]
    resumed_at: int = 0
    already_done: bool = False


def refit_scene(task: RefitTask, settings: RefitSettings, *, progress: bool = True) -> RefitResult:
    """Refit ``task``'s scene with ``settings`` (module docstring).

    Raises:
        UsageError / ProtocolError / DatasetError: bad arguments, a scene or group that does not exist, a camera
            outside the scene bounds.
        PlyError: a fit that does not render this scene's training views.
        CheckpointError: a fit checkpoint that does not hold the PLY, or a refit checkpoint of other inputs.
        EnhancerOutputError: the enhancer returned something other than ``(M, 3, H, W)`` finite images.
    """
    from setdiff_bench.runtime.provenance import device_description, git_revision, package_versions

    settings = settings.check()
    started = time.perf_counter()
    inputs = _inputs(task, settings)
    out = Path(task.out)
    ply, manifest_path, checkpoints = refit_paths(out, inputs.scene_name, inputs.fit_key)
    if manifest_path.is_file():
        done = json.loads(manifest_path.read_text(encoding="utf-8"))
        if done.get("identity") != json.loads(json.dumps(inputs.identity)):
            raise UsageError(
                "holds a finished refit of other inputs or settings; remove it or choose another --out", out
            )
        return RefitResult(ply, manifest_path, done, already_done=True)
    loop = inputs.loop
    resumed_at = loop.step_count if loop.load(checkpoints) else 0
    timing = {"steps_s": 0.0, "updates_s": 0.0, "enhance_s": 0.0}
    updates = settings.update_steps()
    snapshots = set(settings.snapshot_steps())
    from tqdm.auto import tqdm

    from setdiff_bench.gaussians.ply import write_ply

    bar = tqdm(
        total=settings.steps,
        initial=loop.step_count,
        disable=not progress,
        desc="refit",
        unit="step",
        dynamic_ncols=True,
        leave=False,
    )
    try:
        while loop.step_count < settings.steps:
            if loop.updates_done < len(updates) and updates[loop.updates_done] <= loop.step_count:
                tick = time.perf_counter()
                timing["enhance_s"] += inputs.update(loop)
                timing["updates_s"] += time.perf_counter() - tick
                bar.set_postfix(update=loop.updates_done, refresh=False)
            tick = time.perf_counter()
            loss, _ = loop.step()
            timing["steps_s"] += time.perf_counter() - tick
            bar.update(1)
            if loop.step_count % 10 == 0:
                bar.set_postfix(loss=f"{loss:.4f}", update=loop.updates_done, refresh=False)
            if loop.step_count in snapshots:  # before the checkpoint: a resume past it finds it written
                snapshot = snapshot_folder(out, loop.step_count) / inputs.scene_name / ply.name
                snapshot.parent.mkdir(parents=True, exist_ok=True)
                write_ply(snapshot, loop.trainer.params.model().detach())
            if loop.step_count % settings.checkpoint_every == 0 or loop.step_count == settings.steps:
                loop.save(checkpoints)
    finally:
        bar.close()
    from setdiff_bench.evaluation.packet_scoring import peak_memory_bytes
    from setdiff_bench.io.atomic import sha256_file, write_text_atomic

    ply.parent.mkdir(parents=True, exist_ok=True)
    write_ply(ply, loop.trainer.params.model().detach())
    steps_run = settings.steps - resumed_at
    manifest = {
        "format": REFIT_FORMAT,
        "identity": inputs.identity,
        "scene": inputs.scene_name,
        "dataset": task.dataset,
        "protocol": inputs.protocol_name,
        "group": inputs.group_name,
        "fit_key": inputs.fit_key,
        "fit": {"path": str(inputs.fit_path.resolve()), "sha256": inputs.fit_sha},
        "ply": {
            "path": os.path.relpath(ply, out),
            "sha256": sha256_file(ply),
            "gaussians": len(loop.trainer.params),
        },
        "snapshots": [
            {"step": step, "path": os.path.relpath(path, out), "sha256": sha256_file(path)}
            for step in settings.snapshot_steps()
            for path in [snapshot_folder(out, step) / inputs.scene_name / ply.name]
        ],
        "enhancer": inputs.identity["enhancer"],
        "schedule": settings.to_json(),
        "seed": settings.seed,
        "targets": len(inputs.targets),
        "pseudo_views": len(loop.pseudo_cameras),
        "updates": loop.updates_done,
        "training_views": len(loop.trainer.views),
        "resumed_at_step": resumed_at,
        "time": {
            "wall_s": time.perf_counter() - started,
            **timing,
            "s_per_step": timing["steps_s"] / max(1, steps_run),
            "steps_run": steps_run,
        },
        "peak_memory_mb": peak_memory_bytes(torch.device(inputs.device)) / (1 << 20),
        "revision": git_revision(),
        "versions": package_versions(),
        "device": device_description(inputs.device),
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    write_text_atomic(manifest_path, json.dumps(manifest, indent=1, sort_keys=True) + "\n")
    shutil.rmtree(checkpoints, ignore_errors=True)
    return RefitResult(ply, manifest_path, manifest, resumed_at=resumed_at)


@dataclass
class _Inputs:
    """Everything :func:`refit_scene` checked before it writes anything."""

    scene_name: str
    protocol_name: str
    group_name: str
    fit_key: str
    fit_path: Path
    fit_sha: str
    device: str
    targets: list[Any]
    identity: dict[str, Any]
    loop: Any
    update: Any


def _inputs(task: RefitTask, settings: RefitSettings) -> _Inputs:
    """Read and check every input (module docstring, steps 1-4)."""
    from setdiff_bench.enhancers.base import ChecksTargets, available_methods, create_enhancer
    from setdiff_bench.evaluation.run import jsonable_options
    from setdiff_bench.gaussians.fit import FitConfig, load_fit_views
    from setdiff_bench.gaussians.ply import read_ply
    from setdiff_bench.loaders import list_scenes, load_scenes
    from setdiff_bench.packets.fits import FitSource, gaussian_centres
    from setdiff_bench.packets.packing import applicable_groups, scene_extent
    from setdiff_bench.packets.plan import plan_scene
    from setdiff_bench.packets.plan_trajectories import plan_trajectories
    from setdiff_bench.packets.prepare import declared_split, parse_trajectories, resolve_backend
    from setdiff_bench.packets.trajectory import check_within_bounds, scene_bounds
    from setdiff_bench.protocols import load_protocol
    from setdiff_bench.refit.loop import RefitLoop
    from setdiff_bench.refit.packets import target_view
    from setdiff_bench.types import TargetRef, key_fields

    protocol = load_protocol(task.protocol or task.dataset)
    if protocol.dataset != task.dataset:
        raise UsageError(
            f"protocol {protocol.name!r} is for dataset {protocol.dataset!r}, not {task.dataset!r}",
            "--protocol",
        )
    options = {**protocol.loader_options, **task.loader_options}
    assignment = protocol.split.assign(list_scenes(task.dataset, task.root, **options))
    if task.test_scenes is not None:
        assignment = declared_split(assignment, task.test_scenes)
    if task.scene not in assignment:
        shown = ", ".join(sorted(assignment)[:5])
        raise UsageError(f"no scene {task.scene!r} under the root (scenes: {shown})", "--scene")
    scene = load_scenes(task.dataset, task.root, [task.scene], **options)[0]
    groups = applicable_groups(protocol, scene)
    if task.group is not None:
        groups = [protocol.group(task.group)] if any(g.name == task.group for g in groups) else []
        if not groups:
            protocol.group(task.group)  # an unknown name: the protocol's own message lists the groups
            raise UsageError(f"group {task.group!r} does not apply to scene {scene.name!r}", "--group")
    elif task.trajectory is None:
        raise UsageError("give the targets to distil: --group NAME or --trajectory SPEC", "--group")
    fit_keys = sorted({g.fit_key for g in groups})
    if len(fit_keys) != 1:
        raise UsageError(
            f"the scene's groups use fits {', '.join(fit_keys)}; pick one with --group", "--group"
        )
    fit_key = fit_keys[0]
    protocol = dataclasses.replace(protocol, groups=tuple(g for g in groups if g.fit_key == fit_key)[:1])
    if (task.fits is None) == (task.fit_iterations is None):
        raise UsageError(
            "give exactly one of --fits DIR (the scene's fit) or --fit-iterations N (fit here)", "--fits"
        )
    backend, device = resolve_backend(task.backend, task.device)
    source = FitSource(
        fits_dir=task.fits,
        fit=task.fits is None,
        out=Path(task.out) / "base",
        fit_iterations=task.fit_iterations or 1,
        fit_device=device,
        progress=False,
        downscale=protocol.images.downscale,
    )
    fit_frames = protocol.groups[0].select(scene).fit
    source.ensure(scene, fit_key, fit_frames)
    fit_path, fit_sha = source(scene.name, fit_key)
    if task.trajectory is not None:
        specs = parse_trajectories([task.trajectory])
        plans = plan_trajectories(protocol, scene, specs, source, gaussian_centres(source), backend=backend)
    else:
        plans = plan_scene(protocol, scene, assignment[scene.name], source, backend=backend)
    plan = plans[0]
    jobs = [dataclasses.replace(job, targets=tuple(target_view(v) for v in job.targets)) for job in plan.jobs]
    targets = [(j, v) for j, job in enumerate(jobs) for v in job.targets]

    model = read_ply(fit_path)
    views = load_fit_views(scene, [f.name for f in plan.fit_frames], downscale=protocol.images.downscale)
    _check_fit_renders_scene(model, views, settings.min_fit_correlation, fit_path)
    centres, d_max, _, _ = scene_extent(protocol, scene)
    bounds = scene_bounds(model.means.numpy(), centres)
    check_within_bounds([(v.frame, v.camera) for _, v in targets], bounds, f"targets of {plan.group!r}")

    method = available_methods().get(task.method)
    enhancer = create_enhancer(task.method, optional={"device": device}, **task.method_options)
    if isinstance(enhancer, ChecksTargets):  # e.g. precomputed: every image it will be asked for, up front
        enhancer.check_targets(
            [TargetRef(**key_fields(job), frame=v.frame) for job in jobs for v in job.targets]
        )
    files = method.model_files(task.method_options) if method is not None else {}

    config = source.config() if task.fits is None else FitConfig()
    torch_device = torch.device(device)
    trainer, config = _trainer(views, model, config, task.fit_checkpoint, torch_device, settings.seed)
    identity = {
        "dataset": task.dataset,
        "scene": scene.name,
        "protocol": protocol.name,
        "split": assignment[scene.name],
        "group": plan.group,
        "trajectory": task.trajectory,
        "fit_sha256": fit_sha,
        "fit_checkpoint": None if task.fit_checkpoint is None else _checkpoint_sha(task.fit_checkpoint),
        "enhancer": {
            "method": task.method,
            "options": jsonable_options(dict(task.method_options)),
            "files": files,
        },
        # the checkpoint cadence does not change the result: a resume may use another; snapshots are recorded
        # only when asked for, so that refits made before they existed keep their identity
        "settings": {
            k: v
            for k, v in settings.to_json().items()
            if k != "checkpoint_every" and (k != "snapshot_every" or v)
        },
        "backend": backend,
    }
    if task.loader_options:  # only when given, so that refits made before the option keep their identity
        identity["loader_options"] = jsonable_options(dict(task.loader_options))
    from setdiff_bench.refit.updates import PseudoViewUpdater

    updater = PseudoViewUpdater(protocol, plan.fit_frames, jobs, d_max, enhancer, backend, settings, views)
    return _Inputs(
        scene_name=scene.name,
        protocol_name=protocol.name,
        group_name=plan.group,
        fit_key=fit_key,
        fit_path=fit_path,
        fit_sha=fit_sha,
        device=device,
        targets=targets,
        identity=identity,
        loop=RefitLoop(trainer, settings, identity),
        update=updater,
    )


def _check_fit_renders_scene(model: Any, views: list[Any], floor: float, path: Path) -> None:
    """Refuse a fit whose renders do not show the training views' detail: the Pearson correlation of the
    high-pass images (each minus its 5×5 box mean) of render and capture, over the views' masked pixels,
    averaged over views, must reach ``floor``.  Sky and road make any street fit's PSNR look alike; where
    the edges are is what tells one scene's fit from another's."""
    import torch.nn.functional as F

    from setdiff_bench.gaussians.render import render

    def detail(image: torch.Tensor) -> torch.Tensor:
        return image - F.avg_pool2d(image, 5, 1, 2, count_include_pad=False)

    values = []
    with torch.no_grad():
        for view in views:
            rendered = detail(render(model, [view.camera], with_geometry=False).rgb.clamp(0, 1))[0]
            captured = detail(view.image[None])[0]
            keep = torch.ones_like(captured[:1], dtype=torch.bool) if view.mask is None else view.mask
            pair = torch.stack([rendered[keep.expand_as(rendered)], captured[keep.expand_as(captured)]])
            values.append(float(torch.corrcoef(pair)[0, 1]))
    mean = float(np.nanmean(values)) if values else float("nan")
    if not mean >= floor:
        raise PlyError(
            f"the fit's renders of this scene's {len(views)} training views correlate {mean:.2f} with their "
            f"detail, below --min-fit-correlation {floor:g}: a fit of another scene?",
            path,
        )


def _trainer(
    views: list[Any], model: Any, config: Any, checkpoint: Path | None, device: torch.device, seed: int
) -> tuple[Any, Any]:
    """The refit's trainer: the fit's configuration (the checkpoint's when given) without densification, at the
    fit's final position learning rate, all SH bands active, Adam moments from ``checkpoint`` when given."""
    from setdiff_bench.gaussians.fit import STATE_JSON, Trainer, load_checkpoint, saved_config

    names = [v.name for v in views]
    params = None
    if checkpoint is not None:
        json_path = Path(checkpoint) / STATE_JSON
        try:
            state = json.loads(json_path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise CheckpointError(
                f"cannot read the fit checkpoint ({exc.__class__.__name__})", json_path
            ) from exc
        config = saved_config(state, json_path)
        fitted = Trainer(views, model, config, device)
        load_checkpoint(fitted, Path(checkpoint), names)
        held = fitted.params.model().detach()
        if len(held) != len(model) or not all(
            torch.equal(a, b.to(a))
            for a, b in zip(held.tensors().values(), model.tensors().values(), strict=True)
        ):
            raise CheckpointError("the fit checkpoint does not hold the PLY's Gaussians", checkpoint)
        params = fitted.params
    refit_config = dataclasses.replace(
        config, seed=seed, strategy=dataclasses.replace(config.strategy, densify_until=0)
    )
    trainer = Trainer(views, model, refit_config, device)
    if params is not None:
        trainer.params = params
    trainer.params.set_lr("means", config.lr_means_final * trainer.extent)
    trainer.active_sh = model.sh_degree
    return trainer, refit_config


def _checkpoint_sha(folder: Path) -> str:
    from setdiff_bench.gaussians.fit import STATE_JSON
    from setdiff_bench.io.atomic import sha256_file

    path = Path(folder) / STATE_JSON
    if not path.is_file():
        raise CheckpointError("no fit checkpoint here (fit_state.json)", folder)
    return sha256_file(path)
