"""nerfstudio ``transforms.json`` scenes, and the reader DL3DV uses.

File convention (nerfstudio docs; docs/datasets.md, "DL3DV and the 3DGS-Enhancer protocol"):
``transform_matrix`` is camera-to-world in OpenGL camera axes (x right, y up, z back); intrinsics
``fl_x fl_y cx cy`` refer to the stated ``w × h``, globally or per frame; distortion ``k1 k2 p1 p2``
(``camera_model`` OPENCV).  A file written by nerfstudio's ``colmap_to_json`` also permutes the world
(``c2w = A @ c2w_colmap``) and records the permutation ``A`` as a 3×4 ``applied_transform``.

Conversion at this boundary:

* world: with ``world="colmap"`` (default) an ``applied_transform`` is undone, so cameras land in
  the original COLMAP world (the frame of ``sparse/0`` and its points); a uniform scale in it is
  undone too.  ``world="file"`` keeps the file's world.  Without ``applied_transform`` both agree.
* axes: OpenGL → OpenCV by :meth:`Camera.from_opengl_c2w` (stored world-to-camera).
* image: ``file_path`` relative to the folder of ``transforms.json``; with ``images_dir`` the image
  is ``<images_dir>/<basename>`` as nerfstudio's downscale folders (``images_4``) are.
* intrinsics: rescaled per axis to the real image size read from its header when ``images_dir``
  is given (a uniform downscale is required); otherwise the sizes must match exactly.
* distortion: the policy of :mod:`setdiff_bench.loaders.colmap` (``keep`` / ``ignore`` / ``error``).
* missing images: captures made for instant-ngp list frames whose image was removed (instant-ngp
  skips them; its ``fox`` lists 67 frames for 50 photos).  ``missing="error"`` (default) refuses with
  the count and the first file; ``missing="skip"`` leaves them out with one warning.

Frame order of the ``nerfstudio`` dataset: natural order of the frame name (the image path relative
to the scene folder).  JSON is parsed by hand here because no maintained library reads this format
without pulling in nerfstudio itself.
"""

from __future__ import annotations

import math
import os
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any, Literal

import numpy as np

from setdiff_bench.camera_values import float_errors_raised
from setdiff_bench.cameras import Camera
from setdiff_bench.errors import CameraError, DatasetError, DatasetWarning
from setdiff_bench.intrinsics import Distortion, intrinsics_matrix
from setdiff_bench.io.paths import resolve_inside
from setdiff_bench.rotations import check_rotation
from setdiff_bench.types import Frame, Scene

from .colmap import DISTORTION_POLICIES, DistortionPolicy
from .common import (
    dataset_root,
    fit_camera_to_image,
    natural_key,
    read_json,
    require_scenes,
    selected_scene_dirs,
)

WorldFrame = Literal["colmap", "file"]
PINHOLE_MODELS = ("PINHOLE", "SIMPLE_PINHOLE")
DISTORTION_KEYS = ("k1", "k2", "p1", "p2")
MissingPolicy = Literal["error", "skip"]
MISSING_POLICIES: tuple[str, ...] = ("error", "skip")


@dataclass(frozen=True)
class TransformsFrame:
    """One entry of ``transforms.json`` after conversion.

    Attributes:
        index: position in the file's ``frames`` list.
        file_path: the path as written in the file.
        image_path: the image actually used (after ``images_dir``), absolute.
        name: ``image_path`` relative to the folder of ``transforms.json`` (POSIX).
        camera: project convention; intrinsics fitted to the image on disk.
        colmap_im_id: the ``colmap_im_id`` field, or ``None``.
    """

    index: int
    file_path: str
    image_path: Path
    name: str
    camera: Camera
    colmap_im_id: int | None


def read_transforms(
    path: str | os.PathLike[str],
    *,
    images_dir: str | None = None,
    world: WorldFrame = "colmap",
    distortion: DistortionPolicy = "keep",
    missing: MissingPolicy = "error",
) -> list[TransformsFrame]:
    """Read a ``transforms.json`` into cameras in the project convention (module docstring).

    Args:
        path: the ``transforms.json`` file.
        images_dir: replace the folder of every ``file_path`` by this one (``"images_4"``); ``None``
            uses ``file_path`` as written.
        world: ``"colmap"`` undoes ``applied_transform``; ``"file"`` keeps the file's world.
        distortion: ``"keep"``, ``"ignore"`` or ``"error"``.
        missing: ``"error"`` or ``"skip"`` frames whose image file does not exist (module docstring).

    Returns:
        The frames in file order.

    Raises:
        DatasetError: missing file, invalid JSON, missing keys, paths outside the scene folder,
            duplicate frames, an ``applied_transform`` that is not a similarity.
        CameraError / ImageError: invalid poses or intrinsics, image size not matching.
    """
    if world not in ("colmap", "file"):
        raise DatasetError(f"unknown world frame {world!r}; use 'colmap' or 'file'", path)
    if distortion not in DISTORTION_POLICIES:
        raise DatasetError(
            f"unknown distortion policy {distortion!r}; use one of {', '.join(DISTORTION_POLICIES)}", path
        )
    if missing not in MISSING_POLICIES:
        raise DatasetError(
            f"unknown missing-image policy {missing!r}; use one of {', '.join(MISSING_POLICIES)}", path
        )
    transforms = Path(path)
    if not transforms.is_file():
        raise DatasetError("missing transforms.json", transforms)
    meta = read_json(transforms)
    if not isinstance(meta, dict) or not isinstance(meta.get("frames"), list):
        raise DatasetError("expected a JSON object with a 'frames' list", transforms)
    if not meta["frames"]:
        raise DatasetError("'frames' is empty", transforms)
    world_from_file = _undo_applied_transform(meta, transforms) if world == "colmap" else None
    scene_dir = transforms.parent
    out: list[TransformsFrame] = []
    seen: dict[str, int] = {}
    absent: list[Path] = []
    for index, entry in enumerate(meta["frames"]):
        where = f"{transforms} (frames[{index}])"
        if not isinstance(entry, dict):
            raise DatasetError(f"frames[{index}] is not an object", transforms)
        file_path = entry.get("file_path")
        if not isinstance(file_path, str) or not file_path:
            raise DatasetError(f"frames[{index}] has no 'file_path'", transforms)
        relative = file_path if images_dir is None else f"{images_dir}/{PurePosixPath(file_path).name}"
        image_path = resolve_inside(scene_dir, relative, source=transforms)
        name = image_path.relative_to(scene_dir.resolve()).as_posix()
        if name in seen:
            raise DatasetError(
                f"duplicate frame name {name!r} (frames[{seen[name]}] and frames[{index}])", transforms
            )
        seen[name] = index
        if not image_path.is_file():
            absent.append(image_path)
            continue
        K, width, height, lens = _intrinsics(meta, entry, distortion, where)
        c2w = _matrix(entry.get("transform_matrix"), where)
        if world_from_file is not None:
            with float_errors_raised(where):
                c2w = world_from_file(c2w)
        camera = Camera.from_opengl_c2w(c2w, K, width, height, distortion=lens, source=where)
        camera = fit_camera_to_image(camera, image_path, allow_rescale=images_dir is not None)
        colmap_id = entry.get("colmap_im_id")
        out.append(TransformsFrame(index, file_path, image_path, name, camera, _integer_or_none(colmap_id)))
    if absent:
        counted = f"{len(absent)} of {len(meta['frames'])} frames name an image that does not exist"
        if missing == "error" or not out:
            hint = (
                "; pass the loader option missing=skip to leave them out (-o missing=skip; refit: "
                "--loader-option missing=skip)"
                if missing == "error"
                else ""
            )
            raise DatasetError(f"{counted} (first: {absent[0]}){hint}", transforms)
        warnings.warn(
            f"{transforms}: {counted}; skipped (first: {absent[0].name})", DatasetWarning, stacklevel=2
        )
    return out


def _field(meta: Mapping[str, Any], entry: Mapping[str, Any], key: str) -> Any:
    """Per-frame value if present, else the global one (nerfstudio allows both)."""
    return entry[key] if key in entry else meta.get(key)


def _number(value: Any, key: str, where: str, *, required: bool = True, default: float = 0.0) -> float:
    if value is None:
        if required:
            raise DatasetError(f"missing intrinsic {key!r}", where)
        return default
    try:
        number = None if isinstance(value, bool) or not isinstance(value, int | float) else float(value)
    except OverflowError:  # an integer beyond float range
        number = None
    if number is None or not math.isfinite(number):
        raise DatasetError(f"intrinsic {key!r} must be a finite number, got {value!r:.40}", where)
    return number


def _intrinsics(
    meta: Mapping[str, Any], entry: Mapping[str, Any], policy: str, where: str
) -> tuple[np.ndarray, int, int, Distortion | None]:
    width = _number(_field(meta, entry, "w"), "w", where)
    height = _number(_field(meta, entry, "h"), "h", where)
    fx = _number(_field(meta, entry, "fl_x"), "fl_x", where)
    fy = _number(_field(meta, entry, "fl_y"), "fl_y", where, required=False, default=fx)
    cx = _number(_field(meta, entry, "cx"), "cx", where, required=False, default=width / 2.0)
    cy = _number(_field(meta, entry, "cy"), "cy", where, required=False, default=height / 2.0)
    coefficients = tuple(_number(_field(meta, entry, k), k, where, required=False) for k in DISTORTION_KEYS)
    extra = {k: _number(_field(meta, entry, k), k, where, required=False) for k in ("k3", "k4")}
    model = _field(meta, entry, "camera_model") or ("OPENCV" if any(coefficients) else "PINHOLE")
    if model in PINHOLE_MODELS:
        if any(coefficients) or any(extra.values()):
            raise CameraError(f"camera_model {model} but distortion coefficients are non-zero", where)
        lens = None
    elif model == "OPENCV":
        if any(extra.values()):
            raise CameraError(
                f"OPENCV camera with k3/k4 {list(extra.values())} is not supported (only k1 k2 p1 p2)", where
            )
        lens = Distortion("OPENCV", coefficients) if any(coefficients) else None
    else:
        raise CameraError(
            f"unsupported camera_model {model!r}; supported: OPENCV, PINHOLE, SIMPLE_PINHOLE", where
        )
    if lens is not None and policy == "error":
        raise CameraError(
            f"camera has non-zero distortion {list(coefficients)}; undistort the images first or "
            "pass -o distortion=ignore (Python: distortion='ignore')",
            where,
        )
    if policy == "ignore":
        lens = None
    if int(width) != width or int(height) != height:
        raise DatasetError(f"image size must be integers, got w={width:g} h={height:g}", where)
    return intrinsics_matrix(fx, fy, cx, cy), int(width), int(height), lens


def _integer_or_none(value: Any) -> int | None:
    """An integral JSON number as ``int`` (``3`` or ``3.0``), anything else ``None``."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    if isinstance(value, float) and not (math.isfinite(value) and value.is_integer()):
        return None
    return int(value)


def _matrix(value: Any, where: str) -> np.ndarray:
    try:
        matrix = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError) as exc:
        raise DatasetError("'transform_matrix' is not a numeric matrix", where) from exc
    if matrix.shape == (3, 4):
        matrix = np.vstack([matrix, [0.0, 0.0, 0.0, 1.0]])
    if matrix.shape != (4, 4):
        raise DatasetError(f"'transform_matrix' must be 4x4 (or 3x4), got shape {matrix.shape}", where)
    return matrix


def _undo_applied_transform(meta: Mapping[str, Any], transforms: Path):
    """A function mapping a file camera-to-world back to the original world, or ``None`` if none was applied.

    ``applied_transform`` ``A = [s·R | t]`` maps original points ``x`` to file points ``s·R·x + t``;
    a camera with file rotation ``R_f`` and centre ``C_f`` has original rotation ``Rᵀ·R_f`` and centre
    ``Rᵀ·(C_f − t)/s``.
    """
    if meta.get("applied_transform") is None:
        return None
    where = f"{transforms} (applied_transform)"
    A = _matrix(meta["applied_transform"], where)
    if not np.isfinite(A).all():
        raise DatasetError("applied_transform has NaN or infinite values", transforms)
    M, t = A[:3, :3], A[:3, 3]
    with float_errors_raised(where):
        det = float(np.linalg.det(M))
    if not det > 0:
        raise DatasetError(
            f"applied_transform has determinant {det:.4g}; expected a rotation with positive scale",
            transforms,
        )
    scale = det ** (1.0 / 3.0)
    R = M / scale
    try:
        check_rotation(R, where)
    except CameraError as exc:
        raise DatasetError(f"applied_transform is not a similarity ({exc.problem})", transforms) from exc

    def to_original(c2w_file: np.ndarray) -> np.ndarray:
        out = np.eye(4)
        out[:3, :3] = R.T @ c2w_file[:3, :3]
        out[:3, 3] = R.T @ (c2w_file[:3, 3] - t) / scale
        return out

    return to_original


# ---------------------------------------------------------------------- the "nerfstudio" dataset
def is_nerfstudio_scene(folder: Path) -> bool:
    """A folder with ``transforms.json``."""
    return (folder / "transforms.json").is_file()


def _scene_dirs(base: Path) -> dict[str, Path]:
    return require_scenes(base, is_nerfstudio_scene, "nerfstudio", "<scene>/transforms.json")


def list_scenes(root: str | os.PathLike[str]) -> list[str]:
    """Folders under ``root`` (``root`` itself or up to 3 levels down) holding ``transforms.json``."""
    return list(_scene_dirs(dataset_root(root)))


def load_scenes(
    root: str | os.PathLike[str],
    scenes: Iterable[str] | None = None,
    *,
    images_dir: str | None = None,
    world: WorldFrame = "colmap",
    distortion: DistortionPolicy = "keep",
    missing: MissingPolicy = "error",
) -> list[Scene]:
    """Load nerfstudio scenes (see :func:`read_transforms` for the options).

    Returns:
        One :class:`Scene` per name; frames in natural order of their name, no timestamps, one sensor.
    """
    base = dataset_root(root)
    found = _scene_dirs(base)
    out = []
    for name, scene_dir in selected_scene_dirs(found, scenes, base, "nerfstudio"):
        entries = read_transforms(
            scene_dir / "transforms.json",
            images_dir=images_dir,
            world=world,
            distortion=distortion,
            missing=missing,
        )
        frames = tuple(
            Frame(
                name=e.name,
                image_path=e.image_path,
                camera=e.camera,
                metadata={"transforms_index": e.index, "colmap_im_id": e.colmap_im_id},
            )
            for e in sorted(entries, key=lambda e: natural_key(e.name))
        )
        out.append(
            Scene(dataset="nerfstudio", name=name, root=scene_dir, frames=frames, metadata={"world": world})
        )
    return out
