"""An SfM-like sparse point cloud from the world's surfaces, as COLMAP's ``points3D`` would hold it.

Real SfM triangulates surface points seen in at least two training images, colours them with the
mean observed colour, and its error grows with depth.  This sampler does the same with the ground
truth: candidate points are drawn on the surfaces of eligible Gaussians (ground, façades, objects,
foliage — never sky or the far skyline), kept if the depth test passes in at least
``min_views`` training frames (the projected depth lies within the range of rendered depths of the
3×3 pixel neighbourhood, widened by 5 % + 10 cm — one pixel of ground seen at a grazing angle spans
metres of depth at these resolutions),
coloured with the mean observed ground-truth colour, subsampled to ``count`` and perturbed with
isotropic Gaussian noise of ``noise_base_m + noise_per_m · depth`` metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from setdiff_bench.gaussians.backends.torch_ref import quaternion_to_rotation
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.synthetic.capture import CapturedFrame


@dataclass(frozen=True)
class SparsePoints:
    """``xyz (P, 3)`` float64 metres and ``rgb (P, 3)`` uint8."""

    xyz: np.ndarray
    rgb: np.ndarray


def sample_sparse_points(
    static: GaussianModel,
    eligible: torch.Tensor,
    frames: Sequence[CapturedFrame],
    count: int,
    rng: np.random.Generator,
    *,
    min_views: int = 2,
    candidates_per_point: int = 6,
    noise_base_m: float = 0.01,
    noise_per_m: float = 0.003,
) -> SparsePoints:
    """Sample ``count`` noisy, coloured surface points visible in ``frames`` (the training frames).

    Args:
        static: the world's static Gaussians.  eligible: ``(N,)`` bool, Gaussians SfM could triangulate.
        frames: captured training frames (their camera, rgb and depth are used).
        count: number of points wanted (fewer if not enough candidates pass the test).
        rng: the scene's generator.
    """
    ids = np.flatnonzero(eligible.numpy())
    if ids.size == 0 or count <= 0 or not frames:
        return SparsePoints(np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    wanted = count * candidates_per_point
    chosen = rng.choice(ids, size=wanted, replace=ids.size < wanted)
    chosen.sort()
    means = static.means[chosen].double().numpy()
    rotations = quaternion_to_rotation(static.quats[chosen].double()).numpy()
    scales = static.scales[chosen].double().numpy()
    offsets = np.clip(rng.normal(size=(chosen.size, 3)), -1.0, 1.0) * scales
    points = means + np.einsum("nij,nj->ni", rotations, offsets)
    views = np.zeros(points.shape[0], np.int64)
    color_sum = np.zeros((points.shape[0], 3))
    nearest = np.full(points.shape[0], np.inf)
    needed = min(min_views, len(frames))
    for frame in frames:
        uv, z = frame.camera.project(points)
        height, width = frame.depth.shape
        with np.errstate(invalid="ignore"):
            col = np.floor(uv[:, 0])
            row = np.floor(uv[:, 1])
            inside = (z > 0.1) & (col >= 0) & (col < width) & (row >= 0) & (row < height)
        c = np.where(inside, col, 0).astype(np.int64)
        r = np.where(inside, row, 0).astype(np.int64)
        depth = np.where(frame.depth > 0, frame.depth, np.inf).astype(np.float32)
        kernel = np.ones((3, 3), np.uint8)
        near = cv2.erode(depth, kernel)[r, c].astype(np.float64)
        far = cv2.dilate(np.where(np.isinf(depth), 0, depth), kernel)[r, c].astype(np.float64)
        seen = inside & np.isfinite(near) & (z >= 0.95 * near - 0.1) & (z <= 1.05 * far + 0.1)
        views += seen
        color_sum[seen] += frame.rgb[r[seen], c[seen]]
        nearest = np.where(seen, np.minimum(nearest, z), nearest)
    keep = np.flatnonzero(views >= needed)
    if keep.size > count:
        keep = np.sort(rng.choice(keep, size=count, replace=False))
    xyz = points[keep]
    sigma = noise_base_m + noise_per_m * nearest[keep]
    xyz = xyz + rng.normal(size=xyz.shape) * sigma[:, None]
    rgb = np.rint(np.clip(color_sum[keep] / views[keep, None], 0, 1) * 255).astype(np.uint8)
    return SparsePoints(xyz, rgb)
