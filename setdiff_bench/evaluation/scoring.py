"""Scoring enhanced targets against ground truth: image metrics per target, warp error per sequence.

What is scored is what is written: an enhancer's output is quantised to 8 bits exactly as the PNG
writer does (``rint(clip(x, 0, 1) · 255) / 255``) before any metric sees it, so scoring the PNGs
later (``--method precomputed`` on a run's own ``images/``) gives identical numbers — the
nerfbaselines convention of evaluating saved 8-bit predictions (docs/metrics.md, "Evaluation and aggregation").

Image metrics come from :mod:`setdiff_bench.metrics` specs and see the protocol's masks
(True = evaluate).  Warp error (Lai et al. 2018) is a sequence metric: one value per time-ordered
sequence of one camera's targets (flow and occlusion from the ground truth, or, for targets without
ground truth, from the packet's 3DGS renders; see :mod:`setdiff_bench.metrics.warp` and
:mod:`setdiff_bench.evaluation.run._sequences`).
"""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.errors import ImageError, UsageError
from setdiff_bench.metrics.registry import METRICS, PRESETS, MetricSpec
from setdiff_bench.metrics.warp import WarpReference, warp_error, warp_reference
from setdiff_bench.metrics.weights import cache_dir


def quantize(images: torch.Tensor) -> torch.Tensor:
    """``(V, 3, H, W)`` float → float32 on the 8-bit grid, as written to PNG (round to nearest)."""
    return torch.round(images.detach().float().clamp(0.0, 1.0) * 255.0) / 255.0


def to_uint8_hwc(image: torch.Tensor) -> np.ndarray:
    """``(3, H, W)`` float in [0, 1] → ``(H, W, 3)`` uint8 (round to nearest)."""
    return (
        torch.round(image.detach().float().clamp(0.0, 1.0) * 255.0)
        .to(torch.uint8)
        .permute(1, 2, 0)
        .cpu()
        .numpy()
    )


def resolve_metrics(names: str | Sequence[str], *, option: str = "--metrics") -> tuple[MetricSpec, ...]:
    """Image-metric specs from a preset name (``standard``), or a comma list / sequence of metric names.

    ``option`` is what the caller calls the choice, named in errors: the CLI's ``--metrics`` flag by
    default, ``metrics`` for a Python parameter.

    Raises:
        UsageError: an unknown name, a sequence metric (warp error is chosen with ``warp=``), a profile
            metric (``setdiff-bench evaluate`` computes it) or a distribution metric (FID / KID: ``--inception``).
    """
    if isinstance(names, str):
        names = (
            list(PRESETS[names]) if names in PRESETS else [n.strip() for n in names.split(",") if n.strip()]
        )
    warp = "--warp" if option.startswith("--") else "RunSettings.warp"
    specs = []
    for name in names:
        if name not in METRICS:
            raise UsageError(
                f"unknown metric {name!r}; presets: {', '.join(PRESETS)}; metrics: {', '.join(METRICS)}",
                option,
            )
        spec = METRICS[name]
        if spec.scope == "sequence":
            raise UsageError(f"{name} is a sequence metric; it is enabled with {warp}, not {option}", option)
        if spec.scope == "distribution":
            raise UsageError(
                f"{name} is a distribution metric; it is enabled with --inception FILE, not {option}", option
            )
        if spec.scope != "image":
            raise UsageError(
                f"{name} is a {spec.scope} metric; `setdiff-bench evaluate` computes it, not {option}",
                option,
            )
        specs.append(spec)
    if not specs:
        raise UsageError("no metrics selected", option)
    return tuple(specs)


def score_images(
    specs: Sequence[MetricSpec],
    pred: torch.Tensor,
    target: torch.Tensor,
    masks: torch.Tensor,
    batch_size: int,
) -> dict[str, np.ndarray]:
    """Every image metric for ``V`` pairs, ``batch_size`` images per call.

    Args:
        specs: image metric specs.
        pred: ``(V, 3, H, W)`` enhanced images in [0, 1] (already quantised).
        target: ``(V, 3, H, W)`` ground truth in [0, 1].
        masks: ``(V, 1, H, W)`` bool, True = evaluate.
        batch_size: at most this many images per metric call (bounds LPIPS memory).

    Returns:
        metric name → ``(V,)`` float64 values.
    """
    values: dict[str, list[np.ndarray]] = {spec.name: [] for spec in specs}
    with torch.no_grad():
        for start in range(0, pred.shape[0], max(1, batch_size)):
            stop = min(start + max(1, batch_size), pred.shape[0])
            for spec in specs:
                result = spec.compute(pred[start:stop], target[start:stop], masks[start:stop])
                values[spec.name].append(result.detach().double().cpu().numpy().reshape(-1))
    return {name: np.concatenate(parts) if parts else np.zeros(0) for name, parts in values.items()}


def sequence_warp_error(
    frames: torch.Tensor,
    ground_truth: torch.Tensor,
    masks: torch.Tensor | None,
    *,
    flow_method: str = "deepflow",
    cache: Path | None = None,
    gt_key: str | None = None,
    flow_source: str = "ground_truth",
) -> float:
    """Warp error of one time-ordered sequence (paper units: MSE on the 0–255 scale).

    Args:
        frames: ``(T, 3, H, W)`` the method's (quantised) outputs in [0, 1], ``T ≥ 2``, time order.
        ground_truth: ``(T, 3, H, W)`` in [0, 1], the sequence the flow and occlusion come from: the
            matching ground truth, or (``flow_source="render"``, targets without ground truth) the
            packet's 3DGS renders of the same targets.
        masks: ``(T, 1, H, W)`` bool evaluation masks (True = evaluate) or ``None``.
        flow_method: OpenCV optical flow (``deepflow`` default, ``dis`` fast).
        cache: folder for the flow and occlusion (:class:`WarpReference` files), shared by every method
            scored on the same sequence; ``None`` computes it every time.
        gt_key: content key of the flow sequence (e.g. the joined SHA-256 of its files); required with
            ``cache``.
        flow_source: what ``ground_truth`` holds, ``"ground_truth"`` (the default; cache keys as before)
            or ``"render"``, which is part of the cache key, so render flow never reads a
            ground-truth entry or the reverse.
    """
    reference = None
    path = None
    if cache is not None and gt_key:
        key = gt_key if flow_source == "ground_truth" else f"{flow_source}:{gt_key}"
        digest = hashlib.sha256(f"{key}|{flow_method}".encode()).hexdigest()
        path = Path(cache) / f"{digest}.safetensors"
        if path.is_file():
            with contextlib.suppress(ImageError):
                reference = WarpReference.load(path)
            if reference is not None and tuple(reference.flow.shape) != (
                frames.shape[0] - 1,
                2,
                *frames.shape[-2:],
            ):
                reference = None
    if reference is None:
        reference = warp_reference(ground_truth.float().cpu(), method=flow_method)  # type: ignore[arg-type]
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            reference.save(path)
    mask = None if masks is None else masks.cpu()
    return float(warp_error(frames.float().cpu(), reference, mask))


def default_warp_cache() -> Path:
    """``$XDG_CACHE_HOME/setdiff_bench/warp`` (next to the converted LPIPS weights)."""
    return cache_dir() / "warp"
