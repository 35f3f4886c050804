"""Native CPU rasteriser: :mod:`.torch_ref`'s compositing as a compiled C++ kernel with its exact backward.

Written by hand because no maintained library rasterises 3D Gaussians on the CPU (gsplat's kernels
are CUDA-only), and the pure-PyTorch path must evaluate every Gaussian of a tile's list for every
pixel of the tile in padded chunks, with autograd storing each intermediate: a 256×144 fit step
spends ~0.6 s there on one core.  The kernel walks each pixel's depth-sorted list once with early
termination, and its backward pass walks it back to front (gsplat's scheme), recovering each
transmittance by division instead of storing it.

Same maths and conventions as :func:`.torch_ref.rasterize` (projection and tile binning are shared:
this module only replaces the compositing), so the two agree to float32 rounding; the tests compare
values and gradients against the torch path.  Only CPU ``float32`` is handled here.

The C++ source (``cpu_rasterizer.cpp`` beside this file) is compiled on first use with the system
C++ compiler (``$CXX``, else ``g++``/``c++``; about 2 s) into a cache folder keyed by the source's
hash (``$SETDIFF_KERNEL_CACHE``, else ``$XDG_CACHE_HOME/setdiff-bench/kernels``, else
``~/.cache/setdiff-bench/kernels``) and loaded with :mod:`ctypes`.  Without a compiler the torch path
is used and a warning says so.  ``SETDIFF_RASTERIZER`` = ``auto`` (default: this kernel on CPU
float32 when it builds), ``torch`` (always the pure-PyTorch path) or ``native`` (this kernel or an
error).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
import warnings
from pathlib import Path
from typing import Any

import torch

from setdiff_bench.errors import FallbackWarning, UsageError
from setdiff_bench.gaussians.backends import torch_ref

SOURCE = Path(__file__).with_name("cpu_rasterizer.cpp")
COMPILE_FLAGS = ("-O3", "-std=c++17", "-fPIC", "-shared", "-fopenmp", "-fno-math-errno", "-ffp-contract=off")
MODE_ENV = "SETDIFF_RASTERIZER"
MODES = ("auto", "torch", "native")

_library: ctypes.CDLL | None = None
_build_error: str | None = None
_lock = threading.Lock()

_f32 = ctypes.POINTER(ctypes.c_float)
_i64 = ctypes.POINTER(ctypes.c_int64)
_i32 = ctypes.POINTER(ctypes.c_int32)
_COMMON_ARGS = [ctypes.c_int64, ctypes.c_int, _f32, _f32, _f32, _f32, _i64, _i64, _i64] + [ctypes.c_int] * 5


def mode() -> str:
    """The ``SETDIFF_RASTERIZER`` setting (``auto`` when unset); :class:`UsageError` on another value."""
    value = os.environ.get(MODE_ENV, "auto")
    if value not in MODES:
        raise UsageError(f"{MODE_ENV}={value!r}; choose one of {', '.join(MODES)}")
    return value


def handles(features: torch.Tensor) -> bool:
    """Whether compositing these ``(N, C)`` features goes through the native kernel."""
    setting = mode()
    supported = features.device.type == "cpu" and features.dtype == torch.float32
    if setting == "native" and not supported:
        raise UsageError(
            f"{MODE_ENV}=native handles CPU float32 only, got {features.device} {features.dtype}"
        )
    if setting == "torch" or not supported:
        return False
    library = load()
    if library is None and setting == "native":
        raise UsageError(f"{MODE_ENV}=native but the CPU rasteriser did not build: {_build_error}")
    return library is not None


def cache_dir() -> Path:
    """Folder holding compiled kernels."""
    if os.environ.get("SETDIFF_KERNEL_CACHE"):
        return Path(os.environ["SETDIFF_KERNEL_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "setdiff-bench" / "kernels"


def load() -> ctypes.CDLL | None:
    """The compiled kernel library (built on first call), or ``None`` with one warning if it cannot be built."""
    global _library, _build_error
    if _library is not None or _build_error is not None:
        return _library
    with _lock:
        if _library is None and _build_error is None:
            try:
                _library = _bind(ctypes.CDLL(str(_build())))
            except (OSError, subprocess.CalledProcessError, FileNotFoundError) as exc:
                _build_error = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
                warnings.warn(
                    f"native CPU rasteriser unavailable ({_build_error}); using the pure-PyTorch one",
                    FallbackWarning,
                    stacklevel=2,
                )
    return _library


def _compiler() -> str:
    for candidate in (os.environ.get("CXX"), "g++", "c++", "clang++"):
        if candidate and shutil.which(candidate):
            return candidate
    raise FileNotFoundError("no C++ compiler found (set CXX)")


def _build() -> Path:
    """Compile the source into the cache (atomically: concurrent processes may build at once)."""
    source = SOURCE.read_bytes()
    compiler = _compiler()
    key = hashlib.sha256(source + " ".join((compiler, *COMPILE_FLAGS)).encode()).hexdigest()[:16]
    target = cache_dir() / f"cpu_rasterizer-{key}.so"
    if target.exists():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as scratch:
        built = Path(scratch) / target.name
        subprocess.run(
            [compiler, *COMPILE_FLAGS, str(SOURCE), "-o", str(built)],
            check=True,
            capture_output=True,
            text=True,
        )
        os.replace(built, target)
    return target


def _bind(library: ctypes.CDLL) -> ctypes.CDLL:
    library.setdiff_rasterize_forward.argtypes = [*_COMMON_ARGS, _f32, _f32, _f32, _i32, ctypes.c_int]
    library.setdiff_rasterize_forward.restype = ctypes.c_int
    library.setdiff_rasterize_backward.argtypes = [
        *_COMMON_ARGS,
        _f32,
        _i32,
        _f32,
        _f32,
        _f32,
        _f32,
        _f32,
        _f32,
        ctypes.c_int,
    ]
    library.setdiff_rasterize_backward.restype = ctypes.c_int
    return library


def _ptr(tensor: torch.Tensor, kind: Any) -> Any:
    return ctypes.cast(tensor.data_ptr(), kind)


class _Composite(torch.autograd.Function):
    """Differentiable w.r.t. ``means2d``, ``conics``, ``opacities`` and ``features``."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: Any,
        means2d: torch.Tensor,
        conics: torch.Tensor,
        opacities: torch.Tensor,
        features: torch.Tensor,
        binning: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
        tiling: tuple[int, int, int, int, int],
    ) -> tuple[torch.Tensor, torch.Tensor]:
        library = load()
        assert library is not None  # handles() checked it
        tensors = [t.detach().contiguous() for t in (means2d, conics, opacities, features)]
        ids, starts, counts = (t.contiguous() for t in binning)
        width, height, _, _, _ = tiling
        channels = features.shape[1]
        image = torch.empty(height, width, channels, dtype=torch.float32)
        alpha = torch.empty(height, width, dtype=torch.float32)
        final_t = torch.empty(height, width, dtype=torch.float32)
        stop = torch.empty(height, width, dtype=torch.int32)
        library.setdiff_rasterize_forward(
            *_common_arguments(tensors, (ids, starts, counts), tiling),
            _ptr(image, _f32),
            _ptr(alpha, _f32),
            _ptr(final_t, _f32),
            _ptr(stop, _i32),
            torch.get_num_threads(),
        )
        ctx.save_for_backward(*tensors, ids, starts, counts, final_t, stop)
        ctx.tiling = tiling
        return image.permute(2, 0, 1), alpha[None]

    @staticmethod
    def backward(ctx: Any, grad_image: torch.Tensor, grad_alpha: torch.Tensor) -> tuple[Any, ...]:  # type: ignore[override]
        library = load()
        assert library is not None
        means2d, conics, opacities, features, ids, starts, counts, final_t, stop = ctx.saved_tensors
        grads = [torch.zeros_like(t) for t in (means2d, conics, opacities, features)]
        grad_image = grad_image.permute(1, 2, 0).contiguous().float()
        grad_alpha = grad_alpha[0].contiguous().float()
        library.setdiff_rasterize_backward(
            *_common_arguments([means2d, conics, opacities, features], (ids, starts, counts), ctx.tiling),
            _ptr(final_t, _f32),
            _ptr(stop, _i32),
            _ptr(grad_image, _f32),
            _ptr(grad_alpha, _f32),
            *(_ptr(g, _f32) for g in grads),
            torch.get_num_threads(),
        )
        return (*grads, None, None)


def _common_arguments(
    tensors: list[torch.Tensor], binning: tuple[torch.Tensor, ...], tiling: tuple[int, int, int, int, int]
) -> list[Any]:
    means2d, conics, opacities, features = tensors
    return [
        means2d.shape[0],
        features.shape[1],
        *(_ptr(t, _f32) for t in (means2d, conics, opacities, features)),
        *(_ptr(t, _i64) for t in binning),
        *tiling,
    ]


def composite(
    means2d: torch.Tensor,
    conics: torch.Tensor,
    opacities: torch.Tensor,
    features: torch.Tensor,
    binning: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    width: int,
    height: int,
    tile_size: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Composite depth-sorted per-tile lists front to back.

    Args:
        means2d: ``(N, 2)`` pixel centres.  conics: ``(N, 3)`` inverse 2D covariances ``(a, b, c)``.
        opacities: ``(N,)`` activated.  features: ``(N, C)`` values to composite.  All CPU float32.
        binning: ``(sorted_ids (M,), tile_starts (T,), tile_counts (T,))`` int64, as
            :func:`.torch_ref.bin_gaussians` returns them.
        width, height, tile_size: pixels.

    Returns:
        ``image (C, H, W)`` = Σ wᵢ fᵢ and ``alpha (1, H, W)`` = Σ wᵢ.
    """
    tiles_x, tiles_y = -(-width // tile_size), -(-height // tile_size)
    tiling = (width, height, tile_size, tiles_x, tiles_y)
    return _Composite.apply(means2d, conics, opacities, features, binning, tiling)


def rasterize(
    proj: torch_ref.Projection, features: torch.Tensor, width: int, height: int, *, tile_size: int = 8
) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`.torch_ref.rasterize` with the native compositing: same arguments, same outputs."""
    tiles_x, tiles_y = -(-width // tile_size), -(-height // tile_size)
    binning = torch_ref.bin_gaussians(proj, tiles_x, tiles_y, tile_size)
    return composite(proj.means2d, proj.conics, proj.opacities, features, binning, width, height, tile_size)
