"""Packets → model tensors, and the view subsets the trainer draws.

Layout used everywhere in the model: a *set* is N references followed by M targets; several sets of
the same layout stack on a leading batch axis, ``(B, V, ...)`` with V = N + M, flattened "(b v)"
(view-minor) before the networks.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import PacketError
from setdiff_bench.geometry import max_pairwise_distance, overlap_score_matrix, renormalize, snap_to_rays
from setdiff_bench.models.setdiff.geometry_encoder import GEOMETRY_INPUTS, geometry_input
from setdiff_bench.types import Packet, TrainingSample, ViewSet


@dataclass
class SetBatch:
    """B sets of N references + M targets.

    Attributes:
        images: ``(B, V, 3, H, W)`` float32 in [0, 1]; views ``[0, N)`` are references.
        geometry: ``(B, V, 9, H, W)`` C-map + Plücker input of Ψ, or ``None`` (RGB-only model).
        num_references: N.
        points: ``(B, V, 4, H, W)`` surface points × validity and validity (:func:`surface_points`)
            for the C-map distance attention bias, or ``None``.
    """

    images: torch.Tensor
    geometry: torch.Tensor | None
    num_references: int
    points: torch.Tensor | None = None

    @property
    def num_sets(self) -> int:
        return int(self.images.shape[0])

    @property
    def num_views(self) -> int:
        return int(self.images.shape[1])

    @property
    def num_targets(self) -> int:
        return self.num_views - self.num_references

    def to(self, device: torch.device | str, dtype: torch.dtype | None = None) -> SetBatch:
        geometry = None if self.geometry is None else self.geometry.to(device=device, dtype=dtype)
        points = None if self.points is None else self.points.to(device=device, dtype=dtype)
        return SetBatch(self.images.to(device=device, dtype=dtype), geometry, self.num_references, points)


def check_image_size(height: int, width: int, factor: int, where: str) -> None:
    """Reject sizes the VAE cannot map to a latent grid exactly (no silent padding or resizing)."""
    if height % factor or width % factor:
        raise PacketError(
            f"image size {height}x{width} is not divisible by {factor}; resize or crop the packet "
            f"to a multiple of {factor} (e.g. 576x1024)",
            where,
        )


def check_packet(packet: Packet, factor: int) -> None:
    """At least one target; all views the same size, divisible by the latent factor."""
    where = f"packet {packet.packet_id}"
    if len(packet.targets) < 1:
        raise PacketError("packet has no target views", where)
    shapes = {tuple(packet.targets.images.shape[-2:])}
    if len(packet.references):
        shapes.add(tuple(packet.references.images.shape[-2:]))
    if len(shapes) != 1:
        raise PacketError(f"references and targets differ in size: {sorted(shapes)}", where)
    check_image_size(packet.height, packet.width, factor, where)


def view_tensors(
    packet: Packet,
    *,
    use_geometry: bool,
    cmap_clip: float,
    max_references: int | None = None,
    geometry_inputs: Sequence[str] = GEOMETRY_INPUTS,
) -> tuple[torch.Tensor, torch.Tensor | None, int]:
    """All views of a packet, references first.

    Returns:
        images ``(V, 3, H, W)``, geometry ``(V, 9, H, W)`` or ``None``, and N (references used: the
        first ``max_references`` of the packet's, which the packet builder orders best first by Eq. 2).
    """
    references = packet.references
    if max_references is not None and len(references) > max_references:
        references = references.subset(range(max_references))
    views = [v for v in (references, packet.targets) if len(v)]
    images = torch.cat([v.images.float() for v in views])
    geometry = None
    if use_geometry:
        geometry = torch.cat(
            [geometry_input(v.cmaps, v.cameras, cmap_clip=cmap_clip, inputs=geometry_inputs) for v in views]
        )
    return images, geometry, len(references)


#: A pixel has a surface point where the render's alpha exceeds this (the C-map / alpha is then stable).
SURFACE_ALPHA = 0.5


def surface_points(packet: Packet, *, snapped: bool = False) -> torch.Tensor:
    """Per pixel of every view (references first): the surface point ``C-map / alpha`` times its
    validity (alpha > :data:`SURFACE_ALPHA`), and the validity — ``(V, 4, H, W)`` float32, packet units.

    With ``snapped`` the point is moved onto the pixel's ray at its camera depth (:func:`ray_snapped_points`,
    the convention of ``--method reproject``'s ``surface="ray"``), a point at depth ≤ 0 is invalid, and a
    fifth channel holds the pixel's footprint × validity (depth / focal length: the side of one pixel at
    the surface, packet units) — ``(V, 5, H, W)``, for the relative attention bias."""
    views = [v for v in (packet.references, packet.targets) if len(v)]
    cmaps = torch.cat([v.cmaps.float() for v in views])
    alphas = torch.cat([v.alphas.float() for v in views])
    valid = (alphas > SURFACE_ALPHA).float()
    points = cmaps / alphas.clamp_min(SURFACE_ALPHA) * valid
    if not snapped:
        return torch.cat([points, valid], dim=1)
    cameras = [camera for v in views for camera in v.cameras]
    on_rays, footprint = ray_snapped_points(points, cameras)
    valid = valid * (footprint > 0).float()
    return torch.cat([on_rays * valid, valid, footprint.clamp_min(0.0) * valid], dim=1)


def ray_snapped_points(points: torch.Tensor, cameras: Sequence[Camera]) -> tuple[torch.Tensor, torch.Tensor]:
    """Each pixel's point moved onto the pixel's ray at its camera-frame depth ``z``
    (:func:`setdiff_bench.geometry.snap_to_rays`), and the pixel's footprint ``z / √(f_x f_y)`` (focal lengths at
    the image size).

    Args:
        points: ``(V, 3, H, W)`` packet-frame points.
        cameras: the V cameras.

    Returns:
        ``(V, 3, H, W)`` snapped points and ``(V, 1, H, W)`` footprints (negative where ``z`` ≤ 0), float32.
    """
    height, width = int(points.shape[-2]), int(points.shape[-1])
    points = points.float()
    valid = torch.ones((points.shape[0], 1, height, width), dtype=torch.bool, device=points.device)
    snapped = snap_to_rays(points, valid, tuple(cameras))
    footprints = []
    for view, camera in enumerate(cameras):
        R = torch.tensor(camera.R, dtype=torch.float32, device=points.device)
        t = torch.tensor(camera.t, dtype=torch.float32, device=points.device)
        depth = torch.einsum("c,chw->hw", R[2], points[view]) + t[2]
        focal = math.sqrt(camera.K[0, 0] * width / camera.width * camera.K[1, 1] * height / camera.height)
        footprints.append(depth[None] / focal)
    return snapped, torch.stack(footprints)


@dataclass
class TrainingSet:
    """One training set drawn from a :class:`TrainingSample`.

    Attributes:
        batch: one set (B = 1) of N references + M targets.
        target_gt: ``(1, M, 3, H, W)`` ground truth of the targets, in [0, 1].
        target_masks: ``(1, M, 1, H, W)`` bool, True where the loss counts.
    """

    batch: SetBatch
    target_gt: torch.Tensor
    target_masks: torch.Tensor


def choose_views(
    num_references: int,
    num_targets: int,
    rng: random.Random,
    *,
    min_views: int,
    max_views: int,
    max_references: int | None = None,
) -> tuple[list[int], list[int]]:
    """Random subset and order of a packet's views for one training step.

    The set size is uniform in ``[min_views, max_views]`` (capped by what the packet has); references
    and targets keep the packet's proportion, with at least one target and, when the packet has any,
    at least one reference.  Both lists come back randomly permuted (paper: random permutation π).
    """
    available = num_references + num_targets
    size = min(rng.randint(min_views, max_views), available)
    if max_references is not None:
        num_references = min(num_references, max_references)
        size = min(size, num_references + num_targets)
    refs = round(size * num_references / max(num_references + num_targets, 1))
    refs = min(max(refs, 1 if num_references else 0), num_references, size - 1)
    targets = min(size - refs, num_targets)
    refs = min(size - targets, num_references)
    reference_ids = rng.sample(range(num_references), refs)
    target_ids = rng.sample(range(num_targets), targets)
    return reference_ids, target_ids


def best_reference_per_target(packet: Packet) -> list[int]:
    """For each target, the reference with the highest Eq. 2 score against it (DiFix training pairs).

    ``d_max`` is the largest camera-centre distance within the packet.
    """
    cameras = (*packet.references.cameras, *packet.targets.cameras)
    d_max = max_pairwise_distance(np.stack([c.center for c in cameras]))
    scores = overlap_score_matrix(packet.targets.cameras, packet.references.cameras, d_max)
    return [int(np.argmax(row)) for row in scores]


def training_set(
    sample: TrainingSample,
    rng: random.Random,
    *,
    min_views: int,
    max_views: int,
    use_geometry: bool,
    cmap_clip: float,
    pairs: bool = False,
    geometry_inputs: Sequence[str] = GEOMETRY_INPUTS,
    with_points: bool = False,
    snapped_points: bool = False,
    identity_probability: float = 0.0,
    masked_copy_probability: float = 0.0,
    masked_copy_visible: bool = False,
    set_shape: str = "proportional",
    test_targets: tuple[int, int] = (1, 4),
) -> TrainingSet:
    """Draw the views of one training step from ``sample`` and build the tensors.

    A sample with more than ``max_views`` views is subset (:func:`choose_views`); a smaller one (e.g.
    already drawn by the packet store) keeps all its views.  Either way references and targets are
    randomly permuted, and with geometry the set is re-normalised into its first target's frame.

    Args:
        pairs: DiFix mode: one random target and its best reference by Eq. 2 (the training data may
            be permuted, so the packet's first reference need not be the best one).
        with_points: also build the surface points of the attention bias (:func:`surface_points`).
        snapped_points: those points ray-snapped with footprints (the relative bias).
        identity_probability: with this probability the set is an *identity sample*: every target's
            input is its own ground truth, so the model learns to leave a clean view unchanged.
        masked_copy_probability: with this probability (drawn only when the set is not an identity
            sample) the set is a *masked-copy sample*: every target's render loses a rectangle
            (:func:`cut_holes`) while its C-map and rays stay, so the supervised content there can only
            come from the references that see the same surface.
        masked_copy_visible: holes blank only pixels that a reference of the set sees
            (:func:`reference_visibility`).
        set_shape: ``proportional`` (above) or ``test``: all the sample's references and a uniform number of
            targets in ``test_targets`` (capped by the sample's), both randomly permuted.
    """
    packet = sample.packet
    check_packet(packet, 1)
    num_refs, num_targets = len(packet.references), len(packet.targets)
    if pairs:
        target = rng.randrange(num_targets)
        reference_ids = [best_reference_per_target(packet)[target]] if num_refs else []
        target_ids = [target]
    elif set_shape == "test":
        count = min(rng.randint(*test_targets), num_targets)
        reference_ids = rng.sample(range(num_refs), num_refs)
        target_ids = rng.sample(range(num_targets), count)
    elif num_refs + num_targets > max_views:
        reference_ids, target_ids = choose_views(
            num_refs, num_targets, rng, min_views=min_views, max_views=max_views
        )
    else:  # already a set of the wanted size (e.g. drawn by the packet store): only permute
        reference_ids, target_ids = (
            rng.sample(range(num_refs), num_refs),
            rng.sample(range(num_targets), num_targets),
        )
    subset = replace(
        packet,
        references=_subset(packet.references, reference_ids),
        targets=_subset(packet.targets, target_ids),
    )
    if use_geometry:
        subset = renormalize(subset)
    images, geometry, n = view_tensors(
        subset, use_geometry=use_geometry, cmap_clip=cmap_clip, geometry_inputs=geometry_inputs
    )
    gt = sample.target_gt[target_ids].float()[None]
    masks = sample.target_masks[target_ids].bool()[None]
    if identity_probability > 0 and rng.random() < identity_probability:
        images = torch.cat([images[:n], gt[0]])
    elif masked_copy_probability > 0 and rng.random() < masked_copy_probability:
        visible = reference_visibility(subset) if masked_copy_visible else None
        images = torch.cat([images[:n], cut_holes(images[n:], subset.targets.alphas.float(), rng, visible)])
    points = surface_points(subset, snapped=snapped_points)[None] if with_points else None
    batch = SetBatch(images[None], None if geometry is None else geometry[None], n, points)
    return TrainingSet(batch=batch, target_gt=gt, target_masks=masks)


#: Pixel value of a masked-copy hole (mid grey; the C-map and rays of the hole are kept).
HOLE_VALUE = 0.5
#: A masked-copy hole covers this fraction of the image area (uniform), with aspect w/h in HOLE_ASPECT.
HOLE_AREA = (0.08, 0.25)
HOLE_ASPECT = (0.5, 2.0)


def cut_holes(
    images: torch.Tensor, alphas: torch.Tensor, rng: random.Random, visible: torch.Tensor | None = None
) -> torch.Tensor:
    """One rectangular hole per view, filled with :data:`HOLE_VALUE` (the masked-copy task).

    The hole's centre is a random pixel with a surface (alpha > :data:`SURFACE_ALPHA`; any pixel when
    the view has none), so the hole covers geometry that references can see; its area and aspect are
    uniform in :data:`HOLE_AREA` and :data:`HOLE_ASPECT`, clipped at the image border.  With ``visible``
    the centre is drawn among the visible pixels and only the visible pixels of the rectangle are blanked
    (a view with none keeps its render).

    Args:
        images: ``(M, 3, H, W)`` target renders in [0, 1].
        alphas: ``(M, 1, H, W)`` their accumulated opacity.
        rng: the training step's random source.
        visible: ``(M, 1, H, W)`` bool, pixels a reference sees (:func:`reference_visibility`), or ``None``.

    Returns:
        A copy of ``images`` with the holes filled.
    """
    out = images.clone()
    height, width = images.shape[-2:]
    for view in range(images.shape[0]):
        area = rng.uniform(*HOLE_AREA) * height * width
        aspect = rng.uniform(*HOLE_ASPECT)
        hole_h = max(1, min(height, round((area / aspect) ** 0.5)))
        hole_w = max(1, min(width, round((area * aspect) ** 0.5)))
        allowed = alphas[view, 0] > SURFACE_ALPHA if visible is None else visible[view, 0]
        surface = torch.nonzero(allowed)
        if len(surface):
            row, col = (int(v) for v in surface[rng.randrange(len(surface))])
        elif visible is not None:
            continue
        else:
            row, col = rng.randrange(height), rng.randrange(width)
        top = min(max(row - hole_h // 2, 0), height - hole_h)
        left = min(max(col - hole_w // 2, 0), width - hole_w)
        window = (slice(None), slice(top, top + hole_h), slice(left, left + hole_w))
        if visible is None:
            out[view][window] = HOLE_VALUE
        else:
            out[view][window] = torch.where(visible[view][window], HOLE_VALUE, out[view][window])
    return out


#: A reference sees a target pixel when its own surface point at the projection lies within this share of
#: the depth of the target's point (the default of ``--method reproject``).
VISIBILITY_TOLERANCE = 0.03


def reference_visibility(packet: Packet, tolerance: float = VISIBILITY_TOLERANCE) -> torch.Tensor:
    """Which target pixels a reference of ``packet`` sees: ``(M, 1, H, W)`` bool.

    Target and reference surface points are ray-snapped C-map points (:func:`surface_points` with
    ``snapped``).  A target pixel's point ``X`` is projected into each reference (``Camera.project``); the
    reference sees it when the projection lands in the image at positive depth ``z``, the reference has a
    surface point ``Y`` at that (nearest) pixel and ``‖Y − X‖ ≤ tolerance · z`` (no occluder, same surface).
    """
    points = surface_points(packet, snapped=True)
    n = len(packet.references)
    height, width = packet.height, packet.width
    seen = torch.zeros((len(packet.targets), 1, height, width), dtype=torch.bool)
    for view in range(len(packet.targets)):
        target = points[n + view]
        valid = target[3] > 0
        xyz = target[:3].permute(1, 2, 0)[valid].double()  # (P, 3)
        hit = torch.zeros(xyz.shape[0], dtype=torch.bool)
        for ref, camera in enumerate(packet.references.cameras):
            uv, depth = camera.project(xyz.numpy())
            uv_t, z = torch.from_numpy(np.nan_to_num(uv, nan=-1.0)), torch.from_numpy(depth)
            col, row = uv_t[:, 0].floor().long(), uv_t[:, 1].floor().long()
            inside = (z > 0) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
            col, row = col.clamp(0, width - 1), row.clamp(0, height - 1)
            other = points[ref][:, row, col]  # (4, P)
            close = (other[:3].T.double() - xyz).norm(dim=1) <= tolerance * z
            hit |= inside & (other[3] > 0) & close
        seen[view, 0][valid] = hit
    return seen


def _subset(views: ViewSet, indices: Sequence[int]) -> ViewSet:
    return views.subset(list(indices))
