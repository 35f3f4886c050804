"""Warp error (Lai et al., "Learning Blind Video Temporal Consistency", ECCV 2018), batched in torch.

For consecutive frames ``(t−1, t)`` of a method's output ``V``:
``E_t = Σ M_t · (warp(V_t, F_{t−1→t}) − V_{t−1})² / (3 · Σ M_t)`` and the sequence value is the mean of
``E_t`` over its ``T−1`` pairs (a dataset value is the unweighted mean over sequences).  As in the
reference code (phoenix104104/fast_blind_video_consistency ``evaluate_WarpError.py``):

- the flow ``F`` and the non-occlusion mask ``M`` are computed **once on the ground-truth sequence**
  (:func:`warp_reference`), so every method is scored with the same flow and mask.  A sequence without
  ground truth (a novel trajectory) takes them from its 3DGS renders instead, which every method also
  shares (:mod:`setdiff_bench.evaluation.run._sequences`, ``flow_source = "render"``);
- ``warp`` samples frame t at ``x + F(x)`` bilinearly with border clamping (their ``Resample2d``);
- ``M = 1`` except where forward–backward consistency fails,
  ``|F_fw + F_bw(x + F_fw)|² > 0.01 (|F_fw|² + |F_bw(x + F_fw)|²) + 0.5``, or on motion boundaries,
  ``|∇F_fw|² > 0.01 |F_fw|² + 0.002`` with forward differences (``utils.detect_occlusion``);
- a pair with no valid pixel contributes 0 (their ``N = H·W·3`` fallback on an all-zero sum).

One deliberate addition (``OcclusionThresholds.exclude_out_of_frame``, default on): pixels whose flow
target ``x + F(x)`` falls outside the next frame are also excluded.  Lai's code clamps them to the
border and scores them, so a pure camera translation has a non-zero error from the strip that leaves
the view; set the flag to ``False`` to reproduce the original exactly.

Flow comes from OpenCV (DeepFlow by default, see :mod:`.optical_flow`) instead of FlowNet2.

**Scale.** Lai et al.'s native unit is the MSE on [0, 1] images (values ~1e-3…5e-2).  The SetDiff paper
reports 108.9–111.0, which needs a rescaling; we read it as the MSE on a **0–255** scale, i.e.
``scale = 255² = 65025`` (108.9 → RMS ≈ 10 grey levels, consistent with renders at ~21.6 dB PSNR vs GT;
the other reading, ×10⁴ on [0, 1], would mean RMS ≈ 27 levels, larger than the error against ground
truth).  This reading is UNCONFIRMED; ``scale`` is an explicit parameter (``scale=1`` gives Lai's units).
"""

from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass, field

import torch
import torch.nn.functional as F

from setdiff_bench.errors import ImageError
from setdiff_bench.io.atomic import atomic_path
from setdiff_bench.metrics.optical_flow import DEFAULT_FLOW_METHOD, FlowMethod, sequence_flows

#: Our reading of the SetDiff paper's warp-error unit: MSE on a 0–255 scale.
PAPER_SCALE = 255.0**2


@dataclass(frozen=True)
class OcclusionThresholds:
    """Thresholds of the occlusion test (Lai et al. / Sundaram et al. 2010 defaults).

    Occluded where ``|F_fw + F_bw'|² > consistency_ratio·(|F_fw|² + |F_bw'|²) + consistency_offset``
    or ``|∇F_fw|² > boundary_ratio·|F_fw|² + boundary_offset`` (squared magnitudes, pixels²), or, with
    ``exclude_out_of_frame``, where ``x + F_fw(x)`` is outside ``[0, W−1] × [0, H−1]``.
    """

    consistency_ratio: float = 0.01
    consistency_offset: float = 0.5
    boundary_ratio: float = 0.01
    boundary_offset: float = 0.002
    #: also exclude pixels whose target ``x + F(x)`` lies outside the frame (not in Lai et al.'s code)
    exclude_out_of_frame: bool = True


@dataclass
class WarpReference:
    """Flow and validity computed once on a ground-truth sequence of ``T`` frames.

    Attributes:
        flow: ``(T-1, 2, H, W)`` forward flow frame t−1 → t, pixels, on frame t−1's grid.
        valid: ``(T-1, 1, H, W)`` bool, True where the pixel of frame t−1 is not occluded.
        method: flow estimator used (``"deepflow"`` or ``"dis"``).
        thresholds: occlusion thresholds used.
    """

    flow: torch.Tensor
    valid: torch.Tensor
    method: str = DEFAULT_FLOW_METHOD
    thresholds: OcclusionThresholds = field(default_factory=OcclusionThresholds)

    def to(self, device: str | torch.device) -> WarpReference:
        return WarpReference(self.flow.to(device), self.valid.to(device), self.method, self.thresholds)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write flow, mask, method and thresholds to one ``.safetensors`` file (atomically)."""
        from safetensors.torch import save_file

        meta = {
            "format": "setdiff-bench-warp-reference",
            "method": self.method,
            "thresholds": json.dumps(asdict(self.thresholds), sort_keys=True),
        }
        tensors = {
            "flow": self.flow.detach().float().cpu().contiguous(),
            "valid": self.valid.detach().to(torch.uint8).cpu().contiguous(),
        }
        with atomic_path(path) as tmp:
            save_file(tensors, str(tmp), metadata=meta)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> WarpReference:
        """Read a file written by :meth:`save`; :class:`~setdiff_bench.errors.ImageError` if malformed."""
        from safetensors import SafetensorError, safe_open

        try:
            with safe_open(str(path), framework="pt") as handle:
                meta = handle.metadata() or {}
                flow, valid = handle.get_tensor("flow"), handle.get_tensor("valid").bool()
            thresholds = OcclusionThresholds(**json.loads(meta["thresholds"]))
        except (SafetensorError, OSError, KeyError, TypeError, ValueError) as error:
            raise ImageError(f"not a warp reference file: {error}", path) from None
        if (
            meta.get("format") != "setdiff-bench-warp-reference"
            or flow.ndim != 4
            or flow.shape[1] != 2
            or tuple(valid.shape) != (flow.shape[0], 1, *flow.shape[-2:])
        ):
            raise ImageError("not a warp reference file (wrong format tag or tensor shapes)", path)
        return cls(flow, valid, meta.get("method", "unknown"), thresholds)


def pixel_grid(height: int, width: int, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """``(1, 2, H, W)`` pixel coordinates ``(x, y)``."""
    ys, xs = torch.meshgrid(
        torch.arange(height, device=device, dtype=dtype),
        torch.arange(width, device=device, dtype=dtype),
        indexing="ij",
    )
    return torch.stack([xs, ys])[None]


def backward_warp(image: torch.Tensor, flow: torch.Tensor) -> torch.Tensor:
    """Sample ``image`` at ``x + flow(x)``: bilinear, coordinates clamped to the border.

    Args:
        image: ``(N, C, H, W)`` values to sample (frames, or a flow field).
        flow: ``(N, 2, H, W)`` displacements ``(u, v)`` in pixels on the output grid.

    Returns:
        ``(N, C, H, W)`` warped values (differentiable in both arguments).
    """
    _, _, height, width = image.shape
    coords = pixel_grid(height, width, flow.device, flow.dtype) + flow
    # align_corners=True maps pixel index 0 → -1 and W-1 → +1 exactly (pixel centres on integers)
    grid = torch.stack(
        [coords[:, 0] * (2 / max(width - 1, 1)) - 1, coords[:, 1] * (2 / max(height - 1, 1)) - 1], dim=-1
    )
    return F.grid_sample(
        image, grid.to(image.dtype), mode="bilinear", padding_mode="border", align_corners=True
    )


def squared_magnitude(flow: torch.Tensor) -> torch.Tensor:
    """``(N, 2, H, W)`` → ``(N, 1, H, W)`` ``u² + v²``."""
    return flow.square().sum(dim=1, keepdim=True)


def occlusion_mask(
    forward: torch.Tensor, backward: torch.Tensor, thresholds: OcclusionThresholds = OcclusionThresholds()
) -> torch.Tensor:
    """Occluded pixels of the first frame of each pair (forward–backward check + motion boundaries).

    Args:
        forward: ``(N, 2, H, W)`` flow frame a → b on a's grid.
        backward: ``(N, 2, H, W)`` flow frame b → a on b's grid.
        thresholds: see :class:`OcclusionThresholds`.

    Returns:
        ``(N, 1, H, W)`` bool, True = occluded (excluded from the error).
    """
    backward_at_target = backward_warp(backward, forward)
    inconsistent = squared_magnitude(forward + backward_at_target) > (
        thresholds.consistency_ratio * (squared_magnitude(backward_at_target) + squared_magnitude(forward))
        + thresholds.consistency_offset
    )
    # forward differences, zero in the last column / row (utils.compute_flow_gradients)
    du = torch.zeros_like(forward)
    dv = torch.zeros_like(forward)
    du[..., :, :-1] = forward[..., :, :-1] - forward[..., :, 1:]
    dv[..., :-1, :] = forward[..., :-1, :] - forward[..., 1:, :]
    gradient = (du.square() + dv.square()).sum(dim=1, keepdim=True)
    boundary = gradient > thresholds.boundary_ratio * squared_magnitude(forward) + thresholds.boundary_offset
    occluded = inconsistent | boundary
    if thresholds.exclude_out_of_frame:
        height, width = forward.shape[-2:]
        target = pixel_grid(height, width, forward.device, forward.dtype) + forward
        outside = (
            (target[:, :1] < 0)
            | (target[:, :1] > width - 1)
            | (target[:, 1:] < 0)
            | (target[:, 1:] > height - 1)
        )
        occluded = occluded | outside
    return occluded


def warp_reference(
    ground_truth: torch.Tensor,
    method: FlowMethod = DEFAULT_FLOW_METHOD,
    thresholds: OcclusionThresholds = OcclusionThresholds(),
) -> WarpReference:
    """Flow and non-occlusion mask of a ground-truth sequence (compute once, score many methods).

    Args:
        ground_truth: ``(T, 3, H, W)`` RGB in [0, 1], consecutive frames of one camera, ``T ≥ 2``: the
            ground truth, or, for a novel trajectory that has none, the 3DGS renders of its targets.
        method: optical flow estimator (``"deepflow"`` default, ``"dis"`` fast).
        thresholds: occlusion thresholds.

    Returns:
        :class:`WarpReference` on ``ground_truth``'s device.
    """
    forward, backward = sequence_flows(ground_truth, method)
    valid = ~occlusion_mask(forward, backward, thresholds)
    return WarpReference(forward, valid, method, thresholds)


def warp_error_pairs(
    frames: torch.Tensor,
    reference: WarpReference,
    mask: torch.Tensor | None = None,
    *,
    scale: float = PAPER_SCALE,
) -> torch.Tensor:
    """Warp error of each consecutive pair.

    Args:
        frames: ``(T, 3, H, W)`` the method's output sequence in [0, 1] (same size as the reference).
        reference: from :func:`warp_reference` on the ground truth of the same ``T`` frames.
        mask: optional ``(T, 1, H, W)`` evaluation mask (True = evaluate); pair ``(t−1, t)`` uses frame
            t−1's mask together with the non-occlusion mask.
        scale: multiplies the [0, 1]-unit MSE; default :data:`PAPER_SCALE` (0–255 units), 1 = Lai et al.

    Returns:
        ``(T-1,)`` errors.
    """
    if frames.ndim != 4 or frames.shape[0] < 2:
        raise ImageError(f"warp error needs a (T ≥ 2, C, H, W) sequence, got {tuple(frames.shape)}")
    expected = (frames.shape[0] - 1, 2, *frames.shape[-2:])
    if tuple(reference.flow.shape) != expected:
        raise ImageError(
            f"warp error: frames {tuple(frames.shape)} do not match the reference flow "
            f"{tuple(reference.flow.shape)}"
        )
    flow = reference.flow.to(frames.device)
    valid = reference.valid.to(frames.device, frames.dtype)
    if mask is not None:
        if tuple(mask.shape) != (frames.shape[0], 1, *frames.shape[-2:]):
            raise ImageError(
                f"warp error: mask {tuple(mask.shape)} does not match frames {tuple(frames.shape)}"
            )
        valid = valid * mask[:-1].to(frames.device, frames.dtype)
    warped = backward_warp(frames[1:], flow.to(frames.dtype))
    squared = ((warped - frames[:-1]).square() * valid).flatten(1).sum(dim=1)
    count = valid.flatten(1).sum(dim=1) * frames.shape[1]
    return scale * squared / count.clamp(min=1)


def warp_error(
    frames: torch.Tensor,
    reference: WarpReference,
    mask: torch.Tensor | None = None,
    *,
    scale: float = PAPER_SCALE,
) -> torch.Tensor:
    """Warp error of one sequence: mean of :func:`warp_error_pairs` (0-dim tensor)."""
    return warp_error_pairs(frames, reference, mask, scale=scale).mean()
