"""Planning training-pair packets (``prepare --pairs``): recorded frames with their ground truth, rendered
from a 3DGS degraded as a recipe says (:mod:`setdiff_bench.packets.recipes`)."""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any

from setdiff_bench.cameras import Camera
from setdiff_bench.packets.jobs import GroupPlan
from setdiff_bench.packets.packing import group_jobs, scene_extent
from setdiff_bench.packets.plan_trajectories import trajectory_group_name
from setdiff_bench.packets.recipes import PairRecipe, RecipeFrames
from setdiff_bench.packets.working_view import ViewJob, scene_resolution, view_job
from setdiff_bench.protocols import Protocol
from setdiff_bench.types import Frame, Scene


def plan_recipe_pairs(
    protocol: Protocol,
    scene: Scene,
    split: str,
    fit_key: str,
    fit_keys: Sequence[str],
    pairs: Sequence[tuple[PairRecipe, RecipeFrames]],
    fit_path_for: Any,
    *,
    backend: str = "torch",
    cmap_half: bool = False,
) -> list[GroupPlan]:
    """Plan the training-pair packets of one (scene, protocol fit key): one group per recipe
    (:mod:`setdiff_bench.packets.recipes`).

    Each recipe's degraded fit is ``<fit_key><suffix>`` (``lane0@sparse4``).  Its targets are recorded
    frames with their ground truth and mask, cut into packets as the scene's split cuts protocol targets
    (``packets.<split>_views`` minus the references), and each chunk gets the protocol's ``N`` references
    chosen by Eq. 2 (:func:`~setdiff_bench.packets.packing.reference_views`, the scene's ``d_max``) among
    the recorded frames the degraded fit saw.  For ``underfit`` the fit saw every target, and for ``cycle``
    it saw none of the recorded frames (renders at their shifted cameras), so every recorded frame is a
    candidate: in both, a chunk's own targets are left out of its candidates (the clean capture of a target
    is never its reference), ``N`` is at most the recorded frames minus one and a chunk holds at most
    ``recorded frames − N`` targets.

    Args:
        protocol: the protocol.
        scene: the loaded scene.
        split: the scene's split (packet and reference counts).
        fit_key: the protocol fit key whose fit frames are the recorded frames.
        fit_keys: every fit key of the scene's groups (group names get ``@<fit key>`` when several).
        pairs: each recipe with its frames (:func:`~setdiff_bench.packets.recipes.recipe_frames`).
        fit_path_for: ``callable(scene_name, fit_key) -> (Path, sha256)`` of a fit PLY.
        backend, cmap_half: as :func:`plan_scene` (part of the recipe hash).
    """
    resolution = scene_resolution(protocol, scene)
    _, d_max, center, bound = scene_extent(protocol, scene)
    plans = []
    for recipe, frames in pairs:
        degraded_key = f"{fit_key}{frames.fit_suffix}"
        fit_path, fit_sha = fit_path_for(scene.name, degraded_key)
        name = trajectory_group_name(recipe.label, fit_key, fit_keys)
        if frames.disjoint:
            n_ref = min(protocol.references_for(split), len(frames.fit))
            per_packet = protocol.views_for(split) - n_ref
        else:
            n_ref = min(protocol.references_for(split), len(frames.fit) - 1)
            per_packet = min(protocol.views_for(split) - n_ref, len(frames.fit) - n_ref)
        jobs = group_jobs(
            protocol,
            scene,
            group=name,
            split=split,
            fit_key=degraded_key,
            fit_file=(fit_path, fit_sha),
            targets=[(view_job(protocol, f, resolution, target=True), f.camera) for f in frames.targets],
            candidates=partial(_candidates, frames),
            n_ref=n_ref,
            per_packet=per_packet,
            resolution=resolution,
            extent=(d_max, center, bound),
            cmap_half=cmap_half,
            backend=backend,
            pairs=recipe.label,
        )
        plans.append(GroupPlan(scene.name, name, degraded_key, frames.fit, jobs))
    return plans


def _candidates(frames: RecipeFrames, chunk: Sequence[tuple[ViewJob, Camera]]) -> list[Frame]:
    """The recorded frames a chunk's references are chosen from: those the degraded fit saw, less the chunk's own
    targets where the fit saw them too (a target's clean capture is never its reference)."""
    chosen = {view.frame for view, _ in chunk}
    return [f for f in frames.fit if frames.disjoint or f.name not in chosen]
