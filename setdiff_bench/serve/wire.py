"""Messages of ``enhancer.proto`` ↔ tensors and cameras, validating everything a client sends.

Every problem raises :class:`~setdiff_bench.evaluation.stream.StreamInputError` whose path names the field
(``frames[0] 'front' rgb``) and whose problem says what is wrong, so its one line names the field once; the
server answers it with ``INVALID_ARGUMENT``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.evaluation.stream import StreamInputError, Views
from setdiff_bench.serve import enhancer_pb2 as pb

#: dtype names on the wire → numpy dtypes (little endian).
WIRE_DTYPES = {"uint8": np.dtype("uint8"), "float32": np.dtype("<f4")}
#: Largest side of any array a client may send (pixels).
MAX_SIDE = 8192


def to_array(values: np.ndarray) -> pb.Array:
    """``(H, W, C)`` uint8 or float32 array → message."""
    values = np.ascontiguousarray(values)
    dtype = {np.dtype("uint8"): "uint8", np.dtype("float32"): "float32"}.get(values.dtype)
    if dtype is None:
        raise StreamInputError(f"arrays travel as uint8 or float32, got {values.dtype}", "array")
    return pb.Array(
        data=values.astype(WIRE_DTYPES[dtype], copy=False).tobytes(), shape=list(values.shape), dtype=dtype
    )


def from_array(message: pb.Array, what: str, channels: int) -> np.ndarray:
    """Message → ``(H, W, channels)`` array, checking dtype, shape and byte count."""
    if message.dtype not in WIRE_DTYPES:
        raise StreamInputError(f"dtype must be one of {', '.join(WIRE_DTYPES)}, got {message.dtype!r}", what)
    shape = tuple(int(s) for s in message.shape)
    if len(shape) != 3 or shape[2] != channels or not all(0 < s <= MAX_SIDE for s in shape[:2]):
        raise StreamInputError(
            f"shape must be (H, W, {channels}) with 0 < H, W <= {MAX_SIDE}, got {shape}", what
        )
    dtype = WIRE_DTYPES[message.dtype]
    expected = int(np.prod(shape)) * dtype.itemsize
    if len(message.data) != expected:
        raise StreamInputError(
            f"{len(message.data)} bytes for shape {shape} {message.dtype} (expected {expected})", what
        )
    array = np.frombuffer(message.data, dtype=dtype).reshape(shape)
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        raise StreamInputError("contains NaN or infinite values", what)
    return array


def to_camera_message(camera: Camera) -> pb.Camera:
    return pb.Camera(
        intrinsics=camera.K.reshape(-1).tolist(),
        world_to_camera=camera.w2c.reshape(-1).tolist(),
        width=camera.width,
        height=camera.height,
    )


def from_camera_message(message: pb.Camera, what: str) -> Camera:
    if len(message.intrinsics) != 9 or len(message.world_to_camera) != 16:
        raise StreamInputError(
            f"camera needs 9 intrinsics and 16 world_to_camera values, got "
            f"{len(message.intrinsics)} and {len(message.world_to_camera)}",
            what,
        )
    try:
        return Camera(
            K=np.asarray(message.intrinsics, dtype=np.float64).reshape(3, 3),
            w2c=np.asarray(message.world_to_camera, dtype=np.float64).reshape(4, 4),
            width=message.width,
            height=message.height,
            source=what,
        )
    except SetDiffBenchError as error:
        raise StreamInputError(error.problem, what) from None


def to_view(
    name: str,
    rgb: np.ndarray,
    camera: Camera,
    cmap: np.ndarray | None = None,
    alpha: np.ndarray | None = None,
) -> pb.View:
    """One view message: ``rgb`` ``(H, W, 3)`` uint8, ``cmap`` ``(H, W, 3)`` / ``alpha`` ``(H, W, 1)`` float32."""
    view = pb.View(name=name, rgb=to_array(rgb), camera=to_camera_message(camera))
    if cmap is not None:
        view.cmap.CopyFrom(to_array(np.asarray(cmap, dtype=np.float32)))
    if alpha is not None:
        view.alpha.CopyFrom(to_array(np.asarray(alpha, dtype=np.float32)))
    return view


def from_views(messages: Sequence[pb.View], role: str) -> Views:
    """View messages → :class:`~setdiff_bench.evaluation.stream.Views` (C-maps all given or all absent)."""
    if not messages:
        raise StreamInputError("no views", role)
    images, cameras, cmaps, alphas = [], [], [], []
    with_cmaps = {m.HasField("cmap") for m in messages}
    if len(with_cmaps) != 1:
        raise StreamInputError("give C-maps for every view or for none", role)
    for i, message in enumerate(messages):
        what = f"{role}[{i}] {message.name!r}"
        images.append(torch.from_numpy(from_array(message.rgb, f"{what} rgb", 3).copy()).permute(2, 0, 1))
        cameras.append(from_camera_message(message.camera, what))
        if message.HasField("cmap"):
            cmaps.append(
                torch.from_numpy(from_array(message.cmap, f"{what} cmap", 3).copy()).permute(2, 0, 1)
            )
            alpha = (
                from_array(message.alpha, f"{what} alpha", 1)
                if message.HasField("alpha")
                else np.ones((*cmaps[-1].shape[1:], 1), np.float32)
            )
            alphas.append(torch.from_numpy(alpha.copy()).permute(2, 0, 1))
    shapes = {(tuple(t.shape), t.dtype) for t in images}
    if len(shapes) != 1:
        raise StreamInputError(
            f"every rgb must have the same shape and dtype, got {sorted(map(str, shapes))}", role
        )
    try:
        return Views(
            images=torch.stack(images),
            cameras=cameras,
            cmaps=torch.stack(cmaps) if cmaps else None,
            alphas=torch.stack(alphas) if alphas else None,
            names=[m.name or f"view{i}" for i, m in enumerate(messages)],
        )
    except RuntimeError as error:  # C-map sizes differing between views
        raise StreamInputError(str(error).splitlines()[0], role) from None


def images_to_arrays(images: torch.Tensor) -> list[pb.Array]:
    """``(M, 3, H, W)`` float in [0, 1] → M uint8 ``(H, W, 3)`` messages (round to nearest, as ``run`` writes)."""
    quantised = torch.round(images.detach().float().clamp(0, 1) * 255).to(torch.uint8).permute(0, 2, 3, 1)
    return [to_array(q.contiguous().numpy()) for q in quantised]
