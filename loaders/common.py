"""Helpers shared by the dataset loaders: scene discovery and selection, frame order, name lists, image headers.

Image sizes are read from file headers through OpenImageIO (``ImageInput.open(...).spec()``), which
parses only the header, so checking thousands of frames costs milliseconds, not full decodes.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

import OpenImageIO as oiio

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError, ImageError
from setdiff_bench.io.native_stderr import native_stderr_filtered
from setdiff_bench.types import Frame

PathLike = str | os.PathLike[str]

#: Largest mismatch, in pixels, between a rescaled camera size and the real image size that
#: :func:`fit_camera_to_image` accepts when ``allow_rescale`` (``images_4`` of an odd width, say).
RESCALE_TOLERANCE_PX = 1.0

_DIGITS = re.compile(r"(\d+)")


def natural_key(text: str) -> tuple[tuple[int, int | str], ...]:
    """Sort key that orders embedded numbers numerically (``trav_6`` before ``trav_11``).

    Ties between names that differ only in zero padding are broken by the plain string, so the
    order is total and deterministic.
    """
    parts: list[tuple[int, int | str]] = []
    for index, chunk in enumerate(_DIGITS.split(text)):
        if index % 2:
            parts.append((0, int(chunk)))
        elif chunk:
            parts.append((1, chunk))
    parts.append((2, text))
    return tuple(parts)


def frames_by_key(keyed: Iterable[tuple[Any, Frame]]) -> tuple[Frame, ...]:
    """The frames of ``(sort key, frame)`` pairs in key order (a stable sort: equal keys keep their order)."""
    return tuple(frame for _, frame in sorted(keyed, key=lambda item: item[0]))


def require_dir(path: Path, what: str) -> Path:
    """Return ``path`` if it is a folder, else raise ``DatasetError`` naming it."""
    if not path.is_dir():
        raise DatasetError(f"{what} not found (expected a folder)", path)
    return path


def require_file(path: Path, what: str) -> Path:
    """Return ``path`` if it is a file, else raise ``DatasetError`` naming it."""
    if not path.is_file():
        raise DatasetError(f"missing {what}", path)
    return path


def dataset_root(root: PathLike) -> Path:
    """The absolute dataset root; ``DatasetError`` if it is not an existing folder."""
    path = Path(root).expanduser()
    if not path.is_dir():
        raise DatasetError("dataset root not found or not a folder", path)
    return path.resolve()


def find_scene_dirs(root: Path, is_scene: Callable[[Path], bool], *, max_depth: int = 3) -> list[Path]:
    """Folders under ``root`` (``root`` itself included) for which ``is_scene`` holds.

    The search does not descend into a scene folder, skips hidden folders, goes at most
    ``max_depth`` levels below ``root`` and returns the scenes in natural order of their path
    relative to ``root``.
    """
    found: list[Path] = []

    def visit(folder: Path, depth: int) -> None:
        if is_scene(folder):
            found.append(folder)
            return
        if depth >= max_depth:
            return
        try:
            children = [
                entry for entry in os.scandir(folder) if entry.is_dir() and not entry.name.startswith(".")
            ]
        except OSError:
            return
        for entry in children:
            visit(Path(entry.path), depth + 1)

    visit(root, 0)
    return sorted(found, key=lambda p: natural_key(scene_key(root, p)))


def discover_scenes(root: Path, is_scene: Callable[[Path], bool], *, max_depth: int = 3) -> dict[str, Path]:
    """Scene name → folder for every scene :func:`find_scene_dirs` finds, in its order."""
    return {
        scene_key(root, folder): folder for folder in find_scene_dirs(root, is_scene, max_depth=max_depth)
    }


def require_scenes(
    root: Path, is_scene: Callable[[Path], bool], dataset: str, expected: str, *, max_depth: int = 3
) -> dict[str, Path]:
    """:func:`discover_scenes`, raising :class:`DatasetError` ``no <dataset> scenes found (expected <expected>)``
    when there are none."""
    found = discover_scenes(root, is_scene, max_depth=max_depth)
    if not found:
        raise DatasetError(f"no {dataset} scenes found (expected {expected})", root)
    return found


def scene_key(root: Path, scene_dir: Path) -> str:
    """Scene name: the path of ``scene_dir`` relative to ``root`` (POSIX), or the folder name if equal."""
    if scene_dir == root:
        return root.name
    return scene_dir.relative_to(root).as_posix()


def select_scenes(
    available: Sequence[str], requested: Iterable[str] | None, root: Path, dataset: str
) -> list[str]:
    """Resolve requested scene names against the available ones, keeping the request order.

    A request matches a scene by its full name or, when unambiguous, by its last path component
    (``nuplan_vegas_location_1`` for ``Level 1/nuplan_vegas_location_1``).  ``None`` selects all.

    Raises:
        DatasetError: an unknown or ambiguous scene name.
    """
    if requested is None:
        return list(available)
    if isinstance(requested, str):
        requested = [requested]
    chosen: list[str] = []
    for name in requested:
        if name in available:
            match = name
        else:
            matches = [s for s in available if s.rsplit("/", 1)[-1] == name]
            if len(matches) > 1:
                raise DatasetError(f"{dataset} scene name {name!r} is ambiguous: {', '.join(matches)}", root)
            if not matches:
                preview = ", ".join(list(available)[:8]) + (" ..." if len(available) > 8 else "")
                raise DatasetError(f"no {dataset} scene {name!r}; available: {preview or 'none'}", root)
            match = matches[0]
        if match not in chosen:
            chosen.append(match)
    return chosen


def read_json(path: Path, what: str = "file") -> Any:
    """The parsed JSON document at ``path``; :class:`DatasetError` naming the line and column of a syntax error,
    or ``cannot read <what>`` for an unreadable file."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise DatasetError(f"invalid JSON at line {exc.lineno} column {exc.colno}: {exc.msg}", path) from exc
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read {what} ({exc.__class__.__name__})", path) from exc


def selected_scene_dirs(
    found: dict[str, Path], requested: Iterable[str] | None, root: Path, dataset: str
) -> list[tuple[str, Path]]:
    """``(name, folder)`` of the scenes :func:`select_scenes` picks from ``found`` (name → folder)."""
    return [(name, found[name]) for name in select_scenes(list(found), requested, root, dataset)]


def read_name_list(path: Path, *, allow_empty: bool = False) -> list[str]:
    """Read a split file: one image name per line, blank lines and surrounding spaces ignored.

    Raises:
        DatasetError: missing or empty file (unless ``allow_empty``), a name listed twice.
    """
    require_file(path, "split file")
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read split file ({exc.__class__.__name__})", path) from exc
    names: list[str] = []
    seen: set[str] = set()
    for number, line in enumerate(lines, 1):
        name = line.strip()
        if not name:
            continue
        if name in seen:
            raise DatasetError(f"line {number}: duplicate frame name {name!r}", path)
        seen.add(name)
        names.append(name)
    if not names and not allow_empty:
        raise DatasetError("split file is empty (no frame names)", path)
    return names


def image_size(path: Path) -> tuple[int, int]:
    """``(width, height)`` of an image file from its header (no pixel decode).

    Raises:
        ImageError: missing or unreadable file.
    """
    if not path.is_file():
        raise ImageError("image file not found", path)
    oiio.geterror()
    with native_stderr_filtered():  # libpng would print a corrupt header's error a second time
        handle = oiio.ImageInput.open(str(path))
    if handle is None:
        message = (oiio.geterror() or "unknown format").strip().splitlines()
        raise ImageError(f"cannot read image header ({message[0] if message else 'unknown format'})", path)
    try:
        spec = handle.spec()
        return int(spec.width), int(spec.height)
    finally:
        handle.close()


def check_image_matches_camera(path: Path, camera: Camera) -> None:
    """Raise ``ImageError`` unless the image at ``path`` is exactly the camera's size."""
    width, height = image_size(path)
    if (width, height) != (camera.width, camera.height):
        raise ImageError(
            f"image is {width}x{height} (WxH) but its camera is {camera.width}x{camera.height}", path
        )


def fit_camera_to_image(camera: Camera, path: Path, *, allow_rescale: bool) -> Camera:
    """The camera for the image actually on disk.

    Args:
        camera: the camera as the pose file states it (e.g. full-resolution COLMAP intrinsics).
        path: the image file; its header gives the real size.
        allow_rescale: accept an image that is a uniform downscale of the camera's size (``images_4``)
            and scale ``K`` per axis to it (:meth:`Camera.resized`); otherwise sizes must be equal.

    Raises:
        ImageError: sizes differ (and are not a uniform rescale when ``allow_rescale``).
    """
    width, height = image_size(path)
    if (width, height) == (camera.width, camera.height):
        return camera
    if allow_rescale:
        scale = width / camera.width
        if abs(camera.height * scale - height) <= RESCALE_TOLERANCE_PX:
            return camera.resized(width, height)
        raise ImageError(
            f"image is {width}x{height} (WxH), not a uniform rescale of its camera's "
            f"{camera.width}x{camera.height}",
            path,
        )
    raise ImageError(
        f"image is {width}x{height} (WxH) but its camera is {camera.width}x{camera.height}", path
    )


def mask_name_for(image_name: str, suffix: str = ".png") -> str:
    """Mask file name paired by name: the image name with its extension replaced (EUVS: stem + ``.png``)."""
    pure = Path(image_name)
    return (pure.with_suffix(suffix) if pure.suffix else pure.with_name(pure.name + suffix)).as_posix()
