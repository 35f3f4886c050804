"""COLMAP sparse models (binary or text) through pycolmap, and the generic ``colmap`` dataset.

Reading: pycolmap parses both formats, including legacy models without ``rigs``/``frames`` files.
Its binary reader does not notice a cut file, so each ``.bin`` file's size is checked against the size
of the records it declares (:func:`_check_binary_complete`).
Two gaps are filled here: a text model without ``points3D.txt`` (Para-Lane ships only
``cameras.txt`` + ``images.txt``) is read by staging the two files next to an empty point file in a
temporary folder; and since pycolmap's text reader pairs lines blindly (an image line without its
POINTS2D line swallows the next image), the number of image records is cross-checked.

Poses: ``IMAGE_ID QW QX QY QZ TX TY TZ`` are world-to-camera with a scalar-first quaternion in OpenCV
camera axes — already the project convention.  The quaternion's norm must be 1 within 1e-3
(``cameras.QUATERNION_NORM_TOLERANCE``); it is renormalised before use.

Camera models: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL and OPENCV
(:func:`setdiff_bench.cameras.intrinsics_from_colmap`); other models are refused with their name.

Undistortion policy (explicit, per call, parameter ``distortion``):

* ``"keep"`` (default): distortion coefficients stay on :class:`~setdiff_bench.cameras.Camera`
  (``camera.distortion``); ``Camera.project`` applies them, so geometry is exact.  The renderers
  draw ideal pinhole images, so a caller that renders a distorted camera must undistort the images
  first (``colmap image_undistorter``) or choose ``"ignore"``.
* ``"ignore"``: drop the coefficients and treat the camera as a pinhole with the same ``K`` — what
  3DGS-Enhancer does on DL3DV (docs/datasets.md, "DL3DV and the 3DGS-Enhancer protocol").
* ``"error"``: refuse any camera with non-zero distortion.

Frame order of the ``colmap`` dataset: natural order of the COLMAP image name.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError
from setdiff_bench.intrinsics import intrinsics_from_colmap
from setdiff_bench.io.paths import resolve_inside
from setdiff_bench.types import Frame, Scene

from .common import (
    dataset_root,
    fit_camera_to_image,
    natural_key,
    require_dir,
    require_scenes,
    selected_scene_dirs,
)

DistortionPolicy = Literal["keep", "ignore", "error"]
DISTORTION_POLICIES: tuple[str, ...] = ("keep", "ignore", "error")


@dataclass(frozen=True)
class ColmapModel:
    """A COLMAP reconstruction reduced to what the toolkit uses.

    Attributes:
        path: the sparse folder (``sparse/0``).
        cameras: image name → camera (project convention).
        image_ids: image name → COLMAP image id.
        camera_ids: image name → COLMAP camera id.
        points3d: ``(P, 3)`` float64 world points (empty when the model has none).
        points_rgb: ``(P, 3)`` uint8 colours.
        images_file: the ``images.bin`` / ``images.txt`` the poses came from.
    """

    path: Path
    cameras: dict[str, Camera]
    image_ids: dict[str, int]
    camera_ids: dict[str, int]
    points3d: np.ndarray
    points_rgb: np.ndarray
    images_file: Path

    @property
    def num_cameras(self) -> int:
        """Number of distinct COLMAP cameras used by the images."""
        return len(set(self.camera_ids.values()))


def find_sparse_dir(scene_dir: Path) -> Path | None:
    """The model folder of a scene: ``sparse/0`` or ``sparse``, whichever holds a model first."""
    for candidate in (scene_dir / "sparse" / "0", scene_dir / "sparse"):
        if _model_format(candidate) is not None:
            return candidate
    return None


def read_colmap_model(
    sparse_dir: str | os.PathLike[str], *, distortion: DistortionPolicy = "keep"
) -> ColmapModel:
    """Read ``cameras``, ``images`` and (optional) ``points3D``; ``.bin`` preferred, else ``.txt``.

    Args:
        sparse_dir: folder holding the model files.
        distortion: ``"keep"`` distortion on the camera, ``"ignore"`` it (pinhole), or ``"error"`` on any
            (see the module docstring).

    Returns:
        The model; cameras in OpenCV axes, world-to-camera.

    Raises:
        DatasetError: missing files, unreadable model, truncated text records, duplicate names.
        CameraError: a quaternion off unit norm by more than 1e-3, an unsupported camera model.
    """
    if distortion not in DISTORTION_POLICIES:
        raise DatasetError(
            f"unknown distortion policy {distortion!r}; use one of {', '.join(DISTORTION_POLICIES)}",
            sparse_dir,
        )
    sparse = Path(sparse_dir)
    if not sparse.is_dir():
        raise DatasetError("COLMAP sparse folder not found", sparse)
    fmt = _model_format(sparse)
    if fmt is None:
        missing = [
            stem
            for stem in ("cameras", "images")
            if not ((sparse / f"{stem}.bin").is_file() or (sparse / f"{stem}.txt").is_file())
        ]
        raise DatasetError(f"missing COLMAP file {missing[0]}.bin (or {missing[0]}.txt)", sparse)
    ext = ".bin" if fmt == "binary" else ".txt"
    images_file = sparse / f"images{ext}"
    reconstruction = _read_reconstruction(sparse, ext)
    if fmt == "binary":
        _check_binary_complete(sparse, reconstruction)
    if fmt == "text":
        expected = _count_text_image_records(images_file)
        if expected > len(reconstruction.images):  # lost records; (a purely numeric NAME is not counted)
            raise DatasetError(
                f"lists {expected} images but COLMAP's reader parsed {len(reconstruction.images)}; "
                "every image line must be followed by its POINTS2D line (which may be empty)",
                images_file,
            )

    cameras: dict[str, Camera] = {}
    image_ids: dict[str, int] = {}
    camera_ids: dict[str, int] = {}
    for image_id in sorted(reconstruction.images):
        image = reconstruction.images[image_id]
        try:
            image.name  # noqa: B018 - pybind11 decodes the name here
        except UnicodeDecodeError:
            raise DatasetError(f"image {image_id} has a NAME that is not valid UTF-8", images_file) from None
        if image.name in cameras:
            raise DatasetError(
                f"duplicate image name {image.name!r} (ids {image_ids[image.name]} and {image_id})",
                images_file,
            )
        colmap_camera = reconstruction.cameras[image.camera_id]
        source = f"{images_file} (image {image_id} {image.name!r})"
        pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
        K, lens = intrinsics_from_colmap(
            colmap_camera.model.name,
            list(colmap_camera.params),
            source=f"{sparse / f'cameras{ext}'} (camera {image.camera_id})",
        )
        if lens is not None and not lens.is_zero():
            if distortion == "error":
                raise DatasetError(
                    f"camera {image.camera_id} is {colmap_camera.model.name} with non-zero distortion "
                    f"{list(lens.params)}; undistort the images first or pass -o distortion=ignore (Python: distortion='ignore')",
                    sparse / f"cameras{ext}",
                )
            if distortion == "ignore":
                lens = None
        camera = Camera.from_quaternion(
            np.asarray(pose.rotation.quat, dtype=np.float64),
            np.asarray(pose.translation, dtype=np.float64),
            K,
            int(colmap_camera.width),
            int(colmap_camera.height),
            order="xyzw",
            direction="w2c",
            distortion=lens,
            source=source,
        )
        cameras[image.name] = camera
        image_ids[image.name] = int(image_id)
        camera_ids[image.name] = int(image.camera_id)
    ids = sorted(reconstruction.points3D)
    if ids:
        points = np.stack([np.asarray(reconstruction.points3D[i].xyz, dtype=np.float64) for i in ids])
        colors = np.stack([np.asarray(reconstruction.points3D[i].color, dtype=np.uint8) for i in ids])
    else:
        points, colors = np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    return ColmapModel(sparse, cameras, image_ids, camera_ids, points, colors, images_file)


def _model_format(sparse: Path) -> Literal["binary", "text"] | None:
    for ext, name in ((".bin", "binary"), (".txt", "text")):
        if (sparse / f"cameras{ext}").is_file() and (sparse / f"images{ext}").is_file():
            return name  # type: ignore[return-value]
    return None


def _read_reconstruction(sparse: Path, ext: str) -> object:
    """pycolmap reconstruction; a model without ``points3D`` is read from a staged copy with an empty one."""
    import pycolmap

    def read(folder: Path) -> object:
        try:
            return pycolmap.Reconstruction(str(folder))
        except Exception as exc:  # pycolmap raises plain RuntimeError/ValueError for corrupt files
            lines = str(exc).strip().splitlines()
            raise DatasetError(
                f"cannot read COLMAP model ({lines[0] if lines else type(exc).__name__})", sparse
            ) from exc

    if (sparse / f"points3D{ext}").is_file():
        return read(sparse)
    with tempfile.TemporaryDirectory(prefix="setdiff-colmap-") as staging:
        staged = Path(staging)
        for stem in ("cameras", "images", "rigs", "frames"):
            if (sparse / f"{stem}{ext}").is_file():
                shutil.copyfile(sparse / f"{stem}{ext}", staged / f"{stem}{ext}")
        if ext == ".bin":
            (staged / "points3D.bin").write_bytes(np.uint64(0).tobytes())  # point count 0
        else:
            (staged / "points3D.txt").write_text("", encoding="utf-8")
        return read(staged)


def _check_binary_complete(sparse: Path, reconstruction: object) -> None:
    """Refuse truncated or padded ``.bin`` files, which pycolmap's binary reader accepts silently.

    pycolmap fills what a cut file lacks with zeros or stale bytes (a ``cameras.bin`` cut by 3 bytes
    reads as a camera with a wrong ``cy``).  The binary format has no checksum, but its size follows
    from its content: the model parsed is written back to a temporary folder and each file's size is
    compared with the original's (a round trip of a complete file has the same size).
    """
    with tempfile.TemporaryDirectory(prefix="setdiff-colmap-check-") as folder:
        reconstruction.write_binary(folder)  # type: ignore[attr-defined]
        for stem in ("cameras", "images", "points3D", "rigs", "frames"):
            original, rewritten = sparse / f"{stem}.bin", Path(folder) / f"{stem}.bin"
            if original.is_file() and rewritten.is_file():
                size, expected = original.stat().st_size, rewritten.stat().st_size
                if size != expected:
                    raise DatasetError(
                        f"truncated or corrupt COLMAP binary file: {size} bytes, but the records it "
                        f"declares take {expected} bytes",
                        original,
                    )


def _count_text_image_records(images_txt: Path) -> int:
    """Number of image records in ``images.txt``: lines of ≥ 10 fields whose 10th is not a number.

    A POINTS2D line holds only numbers (``X Y POINT3D_ID`` triples), so it never matches.
    """
    count = 0
    with open(images_txt, encoding="utf-8", errors="replace") as handle:
        for line in handle:
            if line.startswith("#"):
                continue
            fields = line.split()
            if len(fields) >= 10:
                try:
                    float(fields[9])
                except ValueError:
                    count += 1
    return count


# ---------------------------------------------------------------------- the generic "colmap" dataset
def is_colmap_scene(folder: Path) -> bool:
    """A folder holding a COLMAP model in ``sparse/0`` or ``sparse``."""
    return find_sparse_dir(folder) is not None


def _scene_dirs(base: Path) -> dict[str, Path]:
    return require_scenes(base, is_colmap_scene, "COLMAP", "<scene>/sparse/0/{cameras,images}.{bin,txt}")


def list_scenes(root: str | os.PathLike[str]) -> list[str]:
    """Scene folders under ``root`` (``root`` itself or up to 3 levels down) holding ``sparse/0`` or ``sparse``."""
    return list(_scene_dirs(dataset_root(root)))


def load_scenes(
    root: str | os.PathLike[str],
    scenes: Iterable[str] | None = None,
    *,
    images_dir: str = "images",
    distortion: DistortionPolicy = "keep",
) -> list[Scene]:
    """Load generic COLMAP scenes: ``<scene>/sparse/0`` + ``<scene>/<images_dir>/<image name>``.

    Args:
        root: dataset root (a scene folder, or a folder of scene folders).
        scenes: scene names from :func:`list_scenes`; ``None`` = all.
        images_dir: image folder inside the scene.  ``images`` must match the model's camera sizes
            exactly; another folder (``images_4``) may be a uniform downscale and the intrinsics are
            rescaled to the real image size.
        distortion: undistortion policy (module docstring).

    Returns:
        One :class:`Scene` per name; frames in natural order of the image name, ``sensor`` =
        ``camera_<id>`` when the model has several cameras, else ``""``.
    """
    base = dataset_root(root)
    found = _scene_dirs(base)
    out = []
    for name, scene_dir in selected_scene_dirs(found, scenes, base, "colmap"):
        sparse = find_sparse_dir(scene_dir)
        assert sparse is not None
        model = read_colmap_model(sparse, distortion=distortion)
        image_root = require_dir(scene_dir / images_dir, "image folder")
        multi = model.num_cameras > 1
        frames = []
        for image_name in sorted(model.cameras, key=natural_key):
            path = resolve_inside(image_root, image_name, source=model.images_file)
            camera = fit_camera_to_image(
                model.cameras[image_name], path, allow_rescale=images_dir != "images"
            )
            frames.append(
                Frame(
                    name=image_name,
                    image_path=path,
                    camera=camera,
                    sensor=f"camera_{model.camera_ids[image_name]}" if multi else "",
                    metadata={"colmap_image_id": model.image_ids[image_name]},
                )
            )
        out.append(
            Scene(
                dataset="colmap",
                name=name,
                root=scene_dir,
                frames=tuple(frames),
                points3d=model.points3d,
                points_rgb=model.points_rgb,
                metadata={"sparse_dir": str(sparse)},
            )
        )
    return out
