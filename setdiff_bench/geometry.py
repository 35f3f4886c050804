"""The paper's geometry: Plücker rays, per-packet pose normalisation, view-overlap score (Eq. 2).

All functions take :class:`~setdiff_bench.cameras.Camera` objects (OpenCV axes, world-to-camera)
and return float32 torch tensors for image-shaped outputs, numpy for small per-camera numbers.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.types import Packet

OVERLAP_ALPHA = 0.8
OVERLAP_BETA = 0.2


def pixel_centers(height: int, width: int) -> np.ndarray:
    """``(H·W, 2)`` float64 pixel-centre coordinates ``(u, v) = (j + 0.5, i + 0.5)``, row-major."""
    v, u = np.meshgrid(np.arange(height) + 0.5, np.arange(width) + 0.5, indexing="ij")
    return np.stack([u.reshape(-1), v.reshape(-1)], axis=1)


def snap_to_rays(points: torch.Tensor, valid: torch.Tensor, cameras: tuple[Camera, ...]) -> torch.Tensor:
    """Move each view's surface points onto their pixels' rays, keeping their camera-frame depth.

    Args:
        points: ``(V, 3, H, W)`` points in the packet frame (e.g. from :func:`cmap_points`).
        valid: ``(V, 1, H, W)`` bool; invalid pixels stay 0.
        cameras: the V cameras.

    Returns:
        ``(V, 3, H, W)``: ``X' = Rᵀ(z · [x_n, y_n, 1] − t)`` with ``z`` the camera-frame depth of ``X`` and
        ``(x_n, y_n)`` the pixel centre's normalised coordinates (undistorted if the camera has distortion).
    """
    height, width = points.shape[-2:]
    snapped = torch.zeros_like(points)
    for v, camera in enumerate(cameras):
        R = torch.tensor(camera.R, dtype=points.dtype, device=points.device)
        t = torch.tensor(camera.t, dtype=points.dtype, device=points.device)
        xn, yn = camera.pixel_to_normalized(pixel_centers(height, width))
        rays = torch.from_numpy(np.stack([xn, yn, np.ones_like(xn)], axis=1)).to(points)  # (HW, 3)
        flat = points[v].reshape(3, -1).T
        depth = (flat @ R.T + t)[:, 2:3]
        world = (rays * depth - t) @ R  # Rᵀ (z d − t) for row vectors
        snapped[v] = torch.where(valid[v], world.T.reshape(3, height, width), torch.zeros_like(points[v]))
    return snapped


def ray_directions(camera: Camera, height: int | None = None, width: int | None = None) -> np.ndarray:
    """Unit world-space ray directions through pixel centres, ``(H, W, 3)`` float64.

    If ``height``/``width`` differ from the camera's size the camera is resized first (K scaled), so
    rays can be computed directly at a lower resolution, e.g. the latent grid.
    """
    cam = _at_size(camera, height, width)
    xn, yn = cam.pixel_to_normalized(pixel_centers(cam.height, cam.width))
    dirs_cam = np.stack([xn, yn, np.ones_like(xn)], axis=1)
    dirs = dirs_cam @ cam.R  # rows: R^T d
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return dirs.reshape(cam.height, cam.width, 3)


def plucker_rays(camera: Camera, height: int | None = None, width: int | None = None) -> torch.Tensor:
    """Plücker embedding ``(o × d, d)`` of every pixel's ray.

    Args:
        camera: the camera (normalise the packet first: the moment ``o × d`` depends on scale).
        height, width: output resolution; default the camera's.  Pixel centres at +0.5.

    Returns:
        ``(6, H, W)`` float32: channels 0–2 the moment ``o × d`` (scene units), 3–5 the unit direction.
    """
    dirs = ray_directions(camera, height, width)
    origin = camera.center
    moment = np.cross(np.broadcast_to(origin, dirs.shape), dirs)
    out = np.concatenate([moment, dirs], axis=2).transpose(2, 0, 1)
    return torch.from_numpy(np.ascontiguousarray(out, dtype=np.float32))


@dataclass(frozen=True)
class NormalizedPacket:
    """Result of :func:`normalize_packet`.

    Attributes:
        cameras: cameras in the new frame (the first target at identity).
        cmaps: ``(V, 3, H, W)`` C-maps in the new frame.
        rotation, translation, scale: the map ``x' = scale · (rotation @ x + translation)``.
    """

    cameras: tuple[Camera, ...]
    cmaps: torch.Tensor
    rotation: np.ndarray
    translation: np.ndarray
    scale: float


def max_pairwise_distance(centers: np.ndarray, chunk: int = 2048) -> float:
    """Largest Euclidean distance between any two rows of ``centers`` ``(P, 3)``; 0 for P < 2."""
    centers = np.asarray(centers, dtype=np.float64)
    best = 0.0
    for start in range(0, len(centers), chunk):
        block = centers[start : start + chunk]
        d2 = ((block[:, None, :] - centers[None, :, :]) ** 2).sum(-1)
        best = max(best, float(d2.max(initial=0.0)))
    return float(np.sqrt(best))


def normalize_packet(
    cameras: Sequence[Camera], cmaps: torch.Tensor, first_target: int, *, alphas: torch.Tensor
) -> NormalizedPacket:
    """Move a packet into the first target camera's frame and scale it to unit extent.

    The new world frame is the camera frame of ``cameras[first_target]`` (which becomes the identity
    pose), scaled so that the largest pairwise camera-centre distance in the packet is 1.  With one
    camera, or all centres coincident, the scale is 1 (documented choice: nothing to normalise).

    C-maps are alpha-weighted sums ``Σ wᵢ xᵢ`` (Eq. 1), so the affine map is applied as
    ``c' = scale · (R c + alpha · t)``; pixels where nothing was hit (alpha = 0) stay exactly zero.

    Args:
        cameras: the V cameras of the packet (references and targets, any order).
        cmaps: ``(V, 3, H, W)`` C-maps in world coordinates.
        first_target: index in ``cameras`` of the first target view.
        alphas: ``(V, 1, H, W)`` accumulated opacities from the same render as ``cmaps``.
    """
    if cmaps.ndim != 4 or cmaps.shape[1] != 3 or len(cameras) != cmaps.shape[0]:
        raise ValueError(f"cmaps must be (V, 3, H, W) with V = {len(cameras)}, got {tuple(cmaps.shape)}")
    anchor = cameras[first_target]
    rotation, translation = anchor.R.copy(), anchor.t.copy()
    centers = np.stack([c.center for c in cameras])
    extent = max_pairwise_distance(centers)
    scale = 1.0 / extent if extent > 1e-12 else 1.0
    new_cameras = tuple(c.with_world_transform(rotation, translation, scale) for c in cameras)
    R = torch.as_tensor(rotation, dtype=torch.float64)
    t = torch.as_tensor(translation, dtype=torch.float64).view(1, 3, 1, 1)
    rotated = torch.einsum("ij,vjhw->vihw", R, cmaps.to(torch.float64))
    new_cmaps = (scale * (rotated + alphas.to(torch.float64) * t)).to(cmaps.dtype)
    return NormalizedPacket(new_cameras, new_cmaps, rotation, translation, scale)


def denormalize_cmaps(
    cmaps: torch.Tensor,
    alphas: torch.Tensor,
    rotation: np.ndarray,
    translation: np.ndarray,
    scale: float,
    *,
    dtype: torch.dtype | None = None,
) -> torch.Tensor:
    """C-maps moved back from a packet's normalised frame to the world frame: the inverse of
    :func:`normalize_packet`'s ``c' = scale · (R c + alpha · t)``, i.e. ``c = Rᵀ (c' / scale − alpha · t)``.

    A stream-API client that sends a stored packet's views needs it (a packet stores its C-maps normalised; the
    session takes world-frame ones), as ``examples/drive_packets.py`` does.  Computed in float64.

    Args:
        cmaps: ``(V, 3, H, W)`` C-maps in the normalised frame (:attr:`NormalizedPacket.cmaps`, a packet's views).
        alphas: ``(V, 1, H, W)`` accumulated opacities of the same render.
        rotation, translation, scale: the map (:class:`NormalizedPacket`; for a stored packet, the anchor
            camera's world ``R``, ``t`` and :attr:`Packet.scale`).
        dtype: of the result (default: ``cmaps``'s).

    Example::

        normalized = normalize_packet(cameras, cmaps, first_target, alphas=alphas)
        world = denormalize_cmaps(
            normalized.cmaps, alphas, normalized.rotation, normalized.translation, normalized.scale
        )  # ≈ cmaps
    """
    # np.array copies: a camera's arrays are read-only, and torch warns on wrapping a non-writable array
    R = torch.from_numpy(np.array(rotation, dtype=np.float64))
    t = torch.from_numpy(np.array(translation, dtype=np.float64)).view(1, 3, 1, 1)
    local = cmaps.to(torch.float64) / scale - alphas.to(torch.float64) * t
    return torch.einsum("ji,vjhw->vihw", R, local).to(dtype or cmaps.dtype)


def view_overlap_score(
    a: Camera, b: Camera, d_max: float, *, alpha: float = OVERLAP_ALPHA, beta: float = OVERLAP_BETA
) -> float:
    """Eq. 2: ``alpha · cos(view_a, view_b) + beta · (1 − ‖c_a − c_b‖ / d_max)``.

    ``d_max`` is the largest pairwise camera-centre distance in the scene; when it is 0 the distance
    term is taken as 1 (all cameras coincide).
    """
    return float(overlap_score_matrix([a], [b], d_max, alpha=alpha, beta=beta)[0, 0])


def overlap_score_matrix(
    targets: Sequence[Camera],
    candidates: Sequence[Camera],
    d_max: float,
    *,
    alpha: float = OVERLAP_ALPHA,
    beta: float = OVERLAP_BETA,
) -> np.ndarray:
    """Eq. 2 for every (target, candidate) pair → ``(T, C)`` float64."""
    vt = np.stack([c.view_direction for c in targets])
    vc = np.stack([c.view_direction for c in candidates])
    cos = (vt @ vc.T) / (np.linalg.norm(vt, axis=1)[:, None] * np.linalg.norm(vc, axis=1)[None, :])
    ct = np.stack([c.center for c in targets])
    cc = np.stack([c.center for c in candidates])
    dist = np.linalg.norm(ct[:, None, :] - cc[None, :, :], axis=-1)
    proximity = 1.0 - dist / d_max if d_max > 0 else np.ones_like(dist)
    return alpha * cos + beta * proximity


def select_references(
    targets: Sequence[Camera],
    candidates: Sequence[Camera],
    n: int,
    *,
    d_max: float | None = None,
    alpha: float = OVERLAP_ALPHA,
    beta: float = OVERLAP_BETA,
    aggregate: Literal["mean", "max"] = "mean",
) -> list[int]:
    """Pick the ``n`` candidates that overlap the packet's targets most (Eq. 2).

    Aggregation over targets: each candidate's score is the **mean** of its Eq. 2 scores against all
    targets of the packet (``aggregate="max"`` takes the best single target instead).  Ties are
    broken by the lower candidate index, so the result is deterministic.

    Args:
        targets: the packet's target cameras.
        candidates: clean frames to choose from (e.g. the 3DGS fit frames).
        n: how many to return (fewer if there are fewer candidates).
        d_max: scene-wide largest pairwise centre distance; default: over targets ∪ candidates.

    Returns:
        candidate indices, best first.
    """
    if not candidates or n <= 0:
        return []
    if d_max is None:
        d_max = max_pairwise_distance(np.stack([c.center for c in (*targets, *candidates)]))
    scores = overlap_score_matrix(targets, candidates, d_max, alpha=alpha, beta=beta)
    per_candidate = scores.mean(axis=0) if aggregate == "mean" else scores.max(axis=0)
    order = np.lexsort((np.arange(len(candidates)), -per_candidate))
    return [int(i) for i in order[:n]]


def _at_size(camera: Camera, height: int | None, width: int | None) -> Camera:
    height = camera.height if height is None else int(height)
    width = camera.width if width is None else int(width)
    if (height, width) == (camera.height, camera.width):
        return camera
    return camera.resized(width, height)


def renormalize(packet: Packet) -> Packet:
    """Move a (sub)set into its first target's frame with unit camera extent — the packet invariant
    (paper supplement "3D Priors") that inference inputs satisfy; C-maps follow the same map."""
    refs, targets = packet.references, packet.targets
    moved = normalize_packet(
        (*refs.cameras, *targets.cameras),
        torch.cat([refs.cmaps, targets.cmaps]),
        len(refs),
        alphas=torch.cat([refs.alphas, targets.alphas]),
    )
    n = len(refs)
    return replace(
        packet,
        scale=packet.scale * moved.scale,
        references=replace(refs, cmaps=moved.cmaps[:n], cameras=moved.cameras[:n]),
        targets=replace(targets, cmaps=moved.cmaps[n:], cameras=moved.cameras[n:]),
    )
