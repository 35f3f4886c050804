"""Evaluation profiles: what gets scored, at what size, and how values are averaged.

A run (:mod:`setdiff_bench.evaluation.run`) scores every target at the protocol's working resolution and a
leaderboard pools per-image values per group: that is the paper's profile (``paper``, the default).
Published baselines score differently, so their numbers are only comparable under their own rules.
A profile states those rules as data; :mod:`setdiff_bench.evaluation.profile_scoring` applies one to a finished
run.  Facts behind each built-in profile, with the official file and commit: docs/evaluation_profiles.md.

Built-in profiles (:data:`PROFILES`):

``paper``
    working resolution (576×1024), protocol masks, ``standard`` metrics, per-image values pooled per
    group, the scene-level test split.
``euvs_official``
    EUVS ``baselines/3DGS/metrics_with_dyn_masks.py``: the 3DGS render size (width capped at 1600,
    :func:`render_size`), ground truth resized with PIL bicubic, masks with nearest, the EUVS metric
    variants (``psnr_euvs, ssim_euvs, lpips_euvs``; plus the DINOv2 cosine and ``Final_Score`` when
    weights are given), a mean per scene over its test images, every scene.
``dl3dv_3dgs_enhancer``
    3DGS-Enhancer ``SVDFor3D/eval.py``: PSNR only, both images centre-cropped to 960×512 from the
    960×540 ``images_4`` frames, a mean per scene, then the mean of scene means per view count.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Literal

import numpy as np

from setdiff_bench.errors import UsageError

if TYPE_CHECKING:
    import pandas as pd

ScoringSize = Literal["working", "render_capped", "native"]
Aggregation = Literal["pooled", "scene_mean"]
SceneSet = Literal["split", "all"]

#: The column naming the profile in every table written under a profile.
PROFILE_COLUMN = "profile"
#: The profile of rows without a ``profile`` column (plain ``run`` output).
DEFAULT_PROFILE = "paper"


@dataclass(frozen=True)
class EvaluationProfile:
    """One way of scoring a run.

    Attributes:
        name: registry key (``--profile``), also written in every table and caption.
        description: one line for listings and captions.
        follows: the official file and commit the profile reproduces (``""`` for ours).
        metrics: image metric names (:data:`setdiff_bench.metrics.registry.METRICS`).
        size: ``"working"`` (the packet store's images), ``"render_capped"`` (the original image brought
            to the 3DGS render size, :func:`render_size` with ``max_width``) or ``"native"`` (the
            original image as stored).
        max_width: the width cap of ``render_capped`` (3DGS: 1600).
        crop: ``(height, width)`` centre crop applied to prediction and ground truth after resizing
            (PIL's box rounding, :func:`centre_crop_box`), or ``None``.
        aggregation: ``"pooled"`` (mean of per-image values per group) or ``"scene_mean"`` (mean per
            scene, then the mean of scene means per group).
        scenes: ``"split"`` (the protocol's scene-level test split) or ``"all"`` (every scene).
        dinov2: the profile adds the EUVS DINOv2 cosine and ``Final_Score`` when weights are given.
    """

    name: str
    description: str
    follows: str
    metrics: tuple[str, ...]
    size: ScoringSize = "working"
    max_width: int | None = None
    crop: tuple[int, int] | None = None
    aggregation: Aggregation = "pooled"
    scenes: SceneSet = "split"
    dinov2: bool = False

    @property
    def needs_dataset(self) -> bool:
        """Whether the original images (``--data``) are needed: the store holds working-size copies only."""
        return self.size != "working"

    def caption(self, size: tuple[int, int] | None = None) -> str:
        """``evaluation profile: <name> (<description>)`` for table captions.

        Args:
            size: ``(height, width)`` the images were scored at, when they share one; a profile scored at
                the working resolution then states it instead of the paper's 576x1024.
        """
        description = self.description
        if size is not None and self.size == "working":
            description = re.sub(r"^\d+x\d+ working", f"{size[0]}x{size[1]} working", description)
        return f"evaluation profile: {self.name} ({description})"


PROFILES: Mapping[str, EvaluationProfile] = MappingProxyType(
    {
        p.name: p
        for p in (
            EvaluationProfile(
                "paper",
                "576x1024 working resolution, per-image values pooled per group, test-split scenes",
                "",
                ("psnr", "ssim", "lpips"),
            ),
            EvaluationProfile(
                "euvs_official",
                "EUVS metrics_with_dyn_masks.py: 3DGS render size (width <= 1600, PIL bicubic GT, "
                "nearest masks), mean per scene, every scene",
                "ai4ce/EUVS-Benchmark@f3b2d907 baselines/3DGS/metrics_with_dyn_masks.py, utils/image_utils.py",
                ("psnr_euvs", "ssim_euvs", "lpips_euvs"),
                size="render_capped",
                max_width=1600,
                aggregation="scene_mean",
                scenes="all",
                dinov2=True,
            ),
            EvaluationProfile(
                "dl3dv_3dgs_enhancer",
                "3DGS-Enhancer eval.py: PSNR on a 960x512 centre crop of 960x540, "
                "mean of scene means per view count",
                "xiliu8006/SVDFor3D@743a1b31 eval.py",
                ("psnr",),
                size="native",
                crop=(512, 960),
                aggregation="scene_mean",
                scenes="split",
            ),
        )
    }
)


def get_profile(name: str) -> EvaluationProfile:
    """The profile called ``name``; a :class:`UsageError` listing the known ones otherwise."""
    try:
        return PROFILES[name]
    except KeyError:
        raise UsageError(
            f"unknown evaluation profile {name!r}; known: {', '.join(PROFILES)}", "--profile"
        ) from None


# ---------------------------------------------------------------------- sizes
def render_size(width: int, height: int, max_width: int = 1600) -> tuple[int, int]:
    """The 3DGS training/render size ``(width, height)`` of an ``width × height`` capture.

    3DGS (``utils/camera_utils.py:loadCam`` with the default ``-r -1``) divides both sides by
    ``width / max_width`` when the width exceeds ``max_width`` and truncates: 1920×1080 → 1600×900,
    1921×1080 → 1600×899.  Smaller images keep their size.
    """
    if width <= max_width:
        return width, height
    scale = width / max_width
    return int(width / scale), int(height / scale)


def centre_crop_box(width: int, height: int, crop_width: int, crop_height: int) -> tuple[int, int, int, int]:
    """``(left, top, right, bottom)`` of a centred ``crop_width × crop_height`` window, as PIL crops it.

    The box ``((W − w)/2, (H − h)/2, (W + w)/2, (H + h)/2)`` is clamped to the image and each edge
    rounded with Python's ``round`` (half to even), which ``PIL.Image.crop`` applies: 960×540 → 512 rows
    from 14 to 526.
    """
    left, top = max(0.0, (width - crop_width) / 2), max(0.0, (height - crop_height) / 2)
    right, bottom = (
        min(float(width), (width + crop_width) / 2),
        min(float(height), (height + crop_height) / 2),
    )
    return round(left), round(top), round(right), round(bottom)


def pil_resize(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``(H, W, 3)`` uint8 → ``(h, w, 3)`` uint8 resized with PIL's bicubic filter (``size = (w, h)``).

    PIL's ``Image.resize`` default for RGB images (Pillow ≥ 7) — what 3DGS's ``PILtoTorch`` uses.
    """
    from PIL import Image

    if (image.shape[1], image.shape[0]) == tuple(size):
        return np.ascontiguousarray(image)
    return np.asarray(Image.fromarray(np.ascontiguousarray(image)).resize(size, Image.Resampling.BICUBIC))


def nearest_resize_mask(mask: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``(H, W)`` bool → ``(h, w)`` bool with ``torch.nn.functional.interpolate(mode="nearest")``
    (source index ``⌊i · H / h⌋``), as the EUVS script resizes its masks (``size = (w, h)``)."""
    import torch
    import torch.nn.functional as F

    tensor = torch.from_numpy(np.ascontiguousarray(mask).astype(np.float32))[None, None]
    return F.interpolate(tensor, size=(size[1], size[0]), mode="nearest")[0, 0].numpy() > 0.5


# ---------------------------------------------------------------------- averaging
def aggregate(
    frame: pd.DataFrame,
    metrics: Sequence[str],
    aggregation: Aggregation,
    keys: Sequence[str] = ("method", "group"),
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Group table and per-scene table of per-image rows.

    Args:
        frame: one row per scored image with ``keys``, ``scene`` and the ``metrics`` columns.
        metrics: metric columns to average.
        aggregation: ``"pooled"``: a group's value is the mean over its images; ``"scene_mean"``: the mean
            over its scenes of each scene's mean over its images (every scene weighs the same).
        keys: the columns a group table row is keyed by.

    Returns:
        ``(groups, scenes)``: ``groups`` has ``keys``, ``scenes`` (count), ``images`` (count) and the
        metrics; ``scenes`` has ``keys``, ``scene``, ``images`` and the per-scene means.
    """
    keys = list(keys)
    metrics = list(metrics)
    scene_keys = [*keys, "scene"]
    scenes = frame.groupby(scene_keys, sort=True)[metrics].mean().reset_index()
    scenes.insert(len(scene_keys), "images", frame.groupby(scene_keys, sort=True).size().to_numpy())
    if aggregation == "scene_mean":
        groups = scenes.groupby(keys, sort=True)[metrics].mean().reset_index()
    elif aggregation == "pooled":
        groups = frame.groupby(keys, sort=True)[metrics].mean().reset_index()
    else:
        raise UsageError(f"unknown aggregation {aggregation!r}; expected pooled or scene_mean")
    counts = (
        scenes.groupby(keys, sort=True).agg(scenes=("scene", "size"), images=("images", "sum")).reset_index()
    )
    groups = groups.merge(counts, on=keys, how="left")
    return groups[[*keys, "scenes", "images", *metrics]], scenes
