"""Dense optical flow for the warp-error metric (OpenCV contrib), and the known-flow check that chose it.

Lai et al. (2018) use FlowNet2, whose CUDA ops do not build on current PyTorch (docs/metrics.md,
"Warp error"); we use OpenCV's classical estimators instead, run once per ground-truth sequence.  Two
were compared on synthetic pairs with exactly known flow (:func:`synthetic_scene_pair`: a photograph
under camera zoom/rotation/translation plus a 64×96 photographed object moving 4–15 px, 288×512, four
cases, end-point error over pixels visible in both frames), on the 2-core development machine while
other jobs ran (``benchmarks/metrics.py`` re-measures it into ``benchmarks/results/metrics.json``):

- DIS, preset MEDIUM: mean EPE 0.235 px (camera motion alone 0.16 px), 0.01–0.04 s per flow;
- DeepFlow: mean EPE **0.104 px** (camera motion alone 0.06 px), 0.4–1.1 s per flow.

DeepFlow is about twice as accurate and is the default.  A warp reference (forward + backward flow and
the occlusion test) costs 8–13 s per frame pair at 576×1024 with DeepFlow and ~1 s with DIS on the
contended 2-core machine; it is computed once per ground-truth sequence (and can be saved with
:meth:`~setdiff_bench.metrics.warp.WarpReference.save`).  DIS stays
available as ``method="dis"`` for long sequences where time matters more.  Known limitation: on small,
low-contrast objects moving several pixels DeepFlow can miss the motion (it returned ~0 for a 32×32
blurred-noise patch moving 6 px, where DIS was right); forward and backward flows then agree, the
occlusion test does not flag those pixels, and they add to the error of every method alike.
"""

from __future__ import annotations

import itertools
from typing import Literal, NamedTuple, get_args

import cv2
import numpy as np
import torch

from setdiff_bench.errors import ImageError, UsageError

FlowMethod = Literal["deepflow", "dis"]
FLOW_METHODS: tuple[str, ...] = get_args(FlowMethod)
DEFAULT_FLOW_METHOD: FlowMethod = "deepflow"


def to_gray_uint8(image: torch.Tensor) -> np.ndarray:
    """``(3, H, W)`` RGB in [0, 1] → ``(H, W)`` uint8 luma (OpenCV ``COLOR_RGB2GRAY``), rounded."""
    rgb = (image.detach().float().clamp(0, 1) * 255).round().to(torch.uint8).permute(1, 2, 0).cpu().numpy()
    return cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY)


def _estimator(method: str) -> cv2.DenseOpticalFlow:
    if method == "deepflow":
        return cv2.optflow.createOptFlow_DeepFlow()
    if method == "dis":
        return cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    raise UsageError(f"unknown optical flow method {method!r}; expected one of {', '.join(FLOW_METHODS)}")


def flow_gray(first: np.ndarray, second: np.ndarray, method: FlowMethod = DEFAULT_FLOW_METHOD) -> np.ndarray:
    """Flow from ``first`` to ``second`` (``(H, W)`` uint8): ``first(y, x) ≈ second(y + v, x + u)``.

    Returns:
        ``(H, W, 2)`` float32 ``(u, v)`` in pixels, defined on ``first``'s pixel grid.
    """
    return _estimator(method).calc(first, second, None)


def sequence_flows(
    frames: torch.Tensor, method: FlowMethod = DEFAULT_FLOW_METHOD
) -> tuple[torch.Tensor, torch.Tensor]:
    """Forward and backward flows between consecutive frames.

    Args:
        frames: ``(T, 3, H, W)`` RGB in [0, 1], ``T ≥ 2`` (any device; flow runs on CPU).
        method: ``"deepflow"`` (default, more accurate) or ``"dis"`` (fast).

    Returns:
        ``(forward, backward)``, each ``(T-1, 2, H, W)`` float32 on ``frames``' device, in pixels:
        ``forward[t]`` maps frame t → t+1 on frame t's grid, ``backward[t]`` maps t+1 → t on frame t+1's.
    """
    if frames.ndim != 4 or frames.shape[1] != 3 or frames.shape[0] < 2:
        raise ImageError(f"optical flow needs a (T ≥ 2, 3, H, W) sequence, got {tuple(frames.shape)}")
    gray = [to_gray_uint8(frame) for frame in frames]
    forward, backward = [], []
    for first, second in itertools.pairwise(gray):
        forward.append(flow_gray(first, second, method))
        backward.append(flow_gray(second, first, method))

    def stack(flows: list[np.ndarray]) -> torch.Tensor:
        return torch.from_numpy(np.stack(flows)).permute(0, 3, 1, 2).contiguous().to(frames.device)

    return stack(forward), stack(backward)


class SyntheticPair(NamedTuple):
    """Two frames with exactly known forward flow.

    Attributes:
        frame0, frame1: ``(H, W, 3)`` float32 RGB in [0, 1].
        flow: ``(H, W, 2)`` float32 forward flow frame0 → frame1 (pixels, on frame0's grid).
        valid: ``(H, W)`` bool, True where the frame-0 pixel is visible in frame 1 (not covered, not out).
    """

    frame0: np.ndarray
    frame1: np.ndarray
    flow: np.ndarray
    valid: np.ndarray


def synthetic_scene_pair(
    texture: np.ndarray,
    size: tuple[int, int],
    rotation: float,
    zoom: float,
    shift: tuple[float, float],
    object_texture: np.ndarray | None = None,
    object_origin: tuple[int, int] = (0, 0),
    object_motion: tuple[int, int] = (0, 0),
) -> SyntheticPair:
    """A photographed background under a known similarity motion, plus an optional moving object.

    Frame 0 samples ``texture`` at ``x + o``; frame 1 at ``A (x − c) + c + b + o`` with ``A = zoom·R(rotation)``,
    ``c`` the image centre, ``b = shift`` and ``o`` centring the frame in the texture (bicubic sampling).  The
    object (an RGB uint8 patch) is pasted at ``object_origin = (x, y)`` in frame 0 and moved by the integer
    ``object_motion = (dx, dy)`` in frame 1, like a car over a camera-motion background.

    Args:
        texture: ``(H_t, W_t, 3)`` uint8 photograph, larger than ``size`` plus the motion.
        size: ``(H, W)`` of the frames.
        rotation: radians; zoom: scale factor; shift: ``(b_x, b_y)`` pixels.
        object_texture, object_origin, object_motion: the optional moving object.

    Returns:
        :class:`SyntheticPair` with the exact flow and the validity of each frame-0 pixel.
    """
    height, width = size
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float64)
    centre = np.array([width / 2, height / 2])
    offset = (np.array(texture.shape[1::-1]) - np.array([width, height])) / 2
    matrix = zoom * np.array([[np.cos(rotation), -np.sin(rotation)], [np.sin(rotation), np.cos(rotation)]])
    image = texture.astype(np.float32) / 255

    def sample(map_x: np.ndarray, map_y: np.ndarray) -> np.ndarray:
        out = cv2.remap(
            image,
            map_x.astype(np.float32),
            map_y.astype(np.float32),
            cv2.INTER_CUBIC,
            borderMode=cv2.BORDER_REFLECT_101,
        )
        return np.clip(out, 0, 1)

    frame0 = sample(xs + offset[0], ys + offset[1])
    local_x, local_y = xs - centre[0], ys - centre[1]
    frame1 = sample(
        matrix[0, 0] * local_x + matrix[0, 1] * local_y + centre[0] + shift[0] + offset[0],
        matrix[1, 0] * local_x + matrix[1, 1] * local_y + centre[1] + shift[1] + offset[1],
    )
    # frame-0 pixel x shows texture point x + o; frame 1 shows it at y with A (y − c) + c + b = x
    inverse = np.linalg.inv(matrix)
    rel_x, rel_y = xs - centre[0] - shift[0], ys - centre[1] - shift[1]
    flow = np.stack(
        [
            inverse[0, 0] * rel_x + inverse[0, 1] * rel_y + centre[0] - xs,
            inverse[1, 0] * rel_x + inverse[1, 1] * rel_y + centre[1] - ys,
        ],
        axis=-1,
    )
    covered = np.zeros((height, width), dtype=bool)
    if object_texture is not None:
        patch = object_texture.astype(np.float32) / 255
        (x0, y0), (dx, dy), (oh, ow) = object_origin, object_motion, patch.shape[:2]
        frame0[y0 : y0 + oh, x0 : x0 + ow] = patch
        frame1[y0 + dy : y0 + dy + oh, x0 + dx : x0 + dx + ow] = patch
        on_object = (xs >= x0) & (xs < x0 + ow) & (ys >= y0) & (ys < y0 + oh)
        target_x, target_y = xs + flow[..., 0], ys + flow[..., 1]
        under_object = (
            (target_x >= x0 + dx)
            & (target_x < x0 + dx + ow)
            & (target_y >= y0 + dy)
            & (target_y < y0 + dy + oh)
        )
        covered = under_object & ~on_object
        flow[on_object] = (dx, dy)
    target_x, target_y = xs + flow[..., 0], ys + flow[..., 1]
    inside = (target_x >= 0) & (target_x <= width - 1) & (target_y >= 0) & (target_y <= height - 1)
    return SyntheticPair(frame0, frame1, flow.astype(np.float32), inside & ~covered)


def endpoint_error(estimate: np.ndarray, truth: np.ndarray, valid: np.ndarray) -> float:
    """Mean end-point error (pixels) of ``(H, W, 2)`` flows over the ``(H, W)`` bool ``valid`` pixels."""
    return float(np.sqrt(((estimate - truth) ** 2).sum(axis=-1))[valid].mean())
