"""Image files through OpenImageIO: 8/16-bit PNG and JPEG in, 8-bit PNG and float EXR out.

In memory, images are float32 numpy arrays ``(H, W, C)`` in [0, 1]; torch code converts to
``(C, H, W)`` with :func:`to_tensor_chw`.  8-bit quantisation rounds to nearest
(``rint(clip(x, 0, 1) * 255)``), the convention of 3DGS' ``save_image``; nerfbaselines truncates
instead, which biases PSNR by up to 1/255 — see README "Metric conventions".
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import numpy as np
import OpenImageIO as oiio
import torch

from setdiff_bench.errors import ImageError
from setdiff_bench.io.atomic import atomic_path
from setdiff_bench.io.native_stderr import native_stderr_filtered

PathLike = str | os.PathLike[str]


def read_image_raw(path: PathLike, dtype: str = "float") -> np.ndarray:
    """Read every channel of an image file.

    Args:
        path: PNG, JPEG, EXR or any format OpenImageIO reads.
        dtype: ``"float"`` (values scaled to [0, 1] for integer files, raw for EXR) or ``"uint8"``.

    Returns:
        ``(H, W, C)`` array, float32 or uint8.

    Raises:
        ImageError: missing, unreadable or truncated file.
    """
    path = Path(path)
    if not path.is_file():
        raise ImageError("file not found", path)
    oiio.geterror()  # clear stale global errors
    with native_stderr_filtered():  # libpng would print its error a second time on stderr
        handle = oiio.ImageInput.open(str(path))
        if handle is None:
            raise ImageError(f"cannot open image ({_first_line(oiio.geterror()) or 'unknown format'})", path)
        try:
            spec = handle.spec()
            fmt = oiio.UINT8 if dtype == "uint8" else oiio.FLOAT
            pixels = handle.read_image(0, 0, 0, spec.nchannels, fmt)
            if pixels is None or handle.has_error:
                raise ImageError(f"corrupt or truncated image ({_first_line(handle.geterror())})", path)
        finally:
            handle.close()
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if pixels.shape[:2] != (spec.height, spec.width) or pixels.shape[2] != spec.nchannels:
        raise ImageError(
            f"decoded shape {pixels.shape} does not match header {spec.height}x{spec.width}", path
        )
    return np.ascontiguousarray(pixels)


def image_size(path: PathLike) -> tuple[int, int] | None:
    """``(height, width)`` from an image file's header (nothing decoded), or ``None`` when unreadable."""
    import OpenImageIO as oiio

    image = oiio.ImageInput.open(str(path))
    if image is None:
        oiio.geterror()  # clear the library's pending error
        return None
    try:
        spec = image.spec()
        return int(spec.height), int(spec.width)
    finally:
        image.close()


def read_rgb(path: PathLike, expected_size: tuple[int, int] | None = None) -> np.ndarray:
    """Read an RGB image as float32 ``(H, W, 3)`` in [0, 1].

    Grayscale files are replicated to three channels; an alpha channel is dropped.

    Args:
        path: the image file.
        expected_size: ``(height, width)`` the image must have (e.g. the camera's), or ``None``.
    """
    pixels = read_image_raw(path, "float")
    channels = pixels.shape[2]
    if channels == 1:
        pixels = np.repeat(pixels, 3, axis=2)
    elif channels == 2:
        pixels = np.repeat(pixels[:, :, :1], 3, axis=2)
    elif channels >= 3:
        pixels = pixels[:, :, :3]
    _check_size(path, pixels, expected_size)
    if not np.isfinite(pixels).all():
        raise ImageError("image contains NaN or infinite values", path)
    return np.clip(pixels, 0.0, 1.0).astype(np.float32)


def read_mask(path: PathLike, expected_size: tuple[int, int] | None = None) -> np.ndarray:
    """Read a single-channel mask as bool ``(H, W)``: True where the 8-bit value is > 127 (EUVS: 255 = keep).

    Multi-channel files use their first channel.
    """
    pixels = read_image_raw(path, "uint8")
    mask = pixels[:, :, 0] > 127
    _check_size(path, mask, expected_size)
    return mask


def read_exr(path: PathLike, channels: int | None = None) -> np.ndarray:
    """Read a float image (EXR) as float32 ``(H, W, C)``; check the channel count if given."""
    pixels = read_image_raw(path, "float").astype(np.float32)
    if channels is not None and pixels.shape[2] != channels:
        raise ImageError(f"expected {channels} channels, found {pixels.shape[2]}", path)
    return pixels


def uint8_to_float(pixels: np.ndarray | torch.Tensor) -> torch.Tensor:
    """8-bit pixels → float32 in [0, 1] exactly as :func:`read_rgb` gives them for an 8-bit file.

    OpenImageIO converts by multiplying with ``float32(1 / 255)`` (not dividing by 255, which differs
    in the last bit for some values); images streamed as bytes must match images read from PNG.
    """
    tensor = torch.as_tensor(pixels)
    return tensor.to(torch.float32) * torch.tensor(1.0 / 255.0, dtype=torch.float32)


def quantize_uint8(image: np.ndarray) -> np.ndarray:
    """Float [0, 1] ``(H, W, C)`` → uint8 by round-to-nearest after clipping."""
    return np.rint(np.clip(np.asarray(image, dtype=np.float32), 0.0, 1.0) * 255.0).astype(np.uint8)


def write_png(path: PathLike, image: np.ndarray, *, atomic: bool = True) -> None:
    """Write an 8-bit PNG atomically (``atomic=False``: directly, for files inside a folder that is
    itself renamed into place).

    Args:
        path: destination ``.png``.
        image: ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)``; uint8, bool or float in [0, 1].
    """
    array = np.asarray(image)
    if array.dtype == np.bool_:
        array = array.astype(np.uint8) * 255
    elif array.dtype != np.uint8:
        array = quantize_uint8(array)
    if array.ndim == 2:
        array = array[:, :, None]
    _write(path, np.ascontiguousarray(array), oiio.UINT8, None, {"png:compressionLevel": 6}, atomic)


def write_exr(
    path: PathLike,
    image: np.ndarray,
    channel_names: tuple[str, ...] | None = None,
    half: bool = False,
    attributes: dict[str, object] | None = None,
    *,
    atomic: bool = True,
) -> None:
    """Write a float EXR atomically (ZIP compression, float32 unless ``half``; ``atomic`` as :func:`write_png`).

    ``attributes`` are extra header attributes; OpenEXR stamps the write time as ``DateTime`` unless one
    is given, so pass e.g. ``{"DateTime": "1970:01:01 00:00:00"}`` for byte-identical files.
    """
    array = np.ascontiguousarray(np.asarray(image, dtype=np.float32))
    if array.ndim == 2:
        array = array[:, :, None]
    _write(
        path,
        array,
        oiio.HALF if half else oiio.FLOAT,
        channel_names,
        {"compression": "zip", **(attributes or {})},
        atomic,
    )


def to_tensor_chw(image: np.ndarray) -> torch.Tensor:
    """``(H, W, C)`` numpy → float32 ``(C, H, W)`` torch tensor."""
    return torch.from_numpy(np.ascontiguousarray(np.asarray(image, dtype=np.float32).transpose(2, 0, 1)))


def to_numpy_hwc(tensor: torch.Tensor) -> np.ndarray:
    """``(C, H, W)`` torch tensor → float32 ``(H, W, C)`` numpy array."""
    return tensor.detach().to("cpu", torch.float32).permute(1, 2, 0).contiguous().numpy()


def _write(
    path: PathLike,
    array: np.ndarray,
    fmt: object,
    channel_names: tuple[str, ...] | None,
    attributes: dict[str, object],
    atomic: bool = True,
) -> None:
    height, width, channels = array.shape
    spec = oiio.ImageSpec(width, height, channels, fmt)
    if channel_names is not None:
        if len(channel_names) != channels:
            raise ValueError(f"{len(channel_names)} channel names for {channels} channels")
        spec.channelnames = tuple(channel_names)
    for key, value in attributes.items():
        spec.attribute(key, value)
    with atomic_path(path) if atomic else contextlib.nullcontext(Path(path)) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise ImageError(f"cannot write image ({_first_line(oiio.geterror())})", path)
        ok = out.write_image(array)
        out.close()
        if not ok:
            raise ImageError(f"cannot write image ({_first_line(out.geterror())})", path)


def _check_size(path: PathLike, pixels: np.ndarray, expected: tuple[int, int] | None) -> None:
    if expected is not None and tuple(pixels.shape[:2]) != tuple(expected):
        raise ImageError(
            f"image is {pixels.shape[1]}x{pixels.shape[0]} (WxH) but its camera is {expected[1]}x{expected[0]}",
            path,
        )


def _first_line(text: str) -> str:
    return (text or "").strip().splitlines()[0] if (text or "").strip() else ""
