"""Synthetic benchmark scenes: the EUVS layout plus ``scene.json`` (docs/synthetic_format.md).

The geometry, split files and masks are read by the EUVS layout reader
(:func:`setdiff_bench.loaders.euvs.load_layout`); ``scene.json`` then supplies, per frame, the
traversal, the camera name (as ``Frame.sensor``), the integer-µs timestamp and, in ``metadata``,
``lane_offset`` (lanes from ``lane0``; ``None`` for lane changes and turns), ``traversal_kind``,
``index`` and ``has_dynamic``.

Cross-checks (each a ``DatasetError`` naming ``scene.json``): the format tag, every model frame has
an entry and every entry a posed frame, the entry's ``split`` equals the set files' designation,
traversal and camera names are declared, and each frame's intrinsics equal its camera's entry.

Frame order: traversal order of ``scene.json``, then camera order of ``scene.json``, then ``index``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from setdiff_bench.errors import DatasetError
from setdiff_bench.types import Frame, Scene

from .colmap import DistortionPolicy
from .common import dataset_root, frames_by_key, read_json, require_scenes, selected_scene_dirs
from .euvs import MaskPolicy, load_layout

FORMAT = "setdiff-synthetic/1"
INTRINSICS_TOLERANCE = 1e-6


def is_synthetic_scene(folder: Path) -> bool:
    """A folder with ``scene.json`` and ``test_set.txt``."""
    return (folder / "scene.json").is_file() and (folder / "test_set.txt").is_file()


def _scene_dirs(base: Path) -> dict[str, Path]:
    return require_scenes(
        base, is_synthetic_scene, "synthetic", "<scene>/scene.json and <scene>/test_set.txt"
    )


def list_scenes(root: str | os.PathLike[str]) -> list[str]:
    """Synthetic scene folders under ``root`` (itself or up to 3 levels down)."""
    return list(_scene_dirs(dataset_root(root)))


def read_scene_json(path: Path) -> dict[str, Any]:
    """Parse and check the top level of ``scene.json``."""
    meta = read_json(path)
    if not isinstance(meta, dict):
        raise DatasetError("expected a JSON object", path)
    if meta.get("format") != FORMAT:
        raise DatasetError(f"format is {meta.get('format')!r}, expected {FORMAT!r}", path)
    for key in ("traversals", "cameras", "frames"):
        if not isinstance(meta.get(key), list) or not meta[key]:
            raise DatasetError(f"'{key}' must be a non-empty list", path)
    return meta


def load_scenes(
    root: str | os.PathLike[str],
    scenes: Iterable[str] | None = None,
    *,
    masks: MaskPolicy = "require_test",
    distortion: DistortionPolicy = "keep",
) -> list[Scene]:
    """Load synthetic scenes.

    Args:
        root: the generator's output folder.
        scenes: names from :func:`list_scenes`; ``None`` = all.
        masks: mask policy of the EUVS reader (the generator writes a mask for every frame).
        distortion: undistortion policy (the generator writes PINHOLE cameras).
    """
    base = dataset_root(root)
    found = _scene_dirs(base)
    return [
        _load_one(scene_dir, name, masks, distortion)
        for name, scene_dir in selected_scene_dirs(found, scenes, base, "synthetic")
    ]


def _load_one(scene_dir: Path, name: str, masks: MaskPolicy, distortion: DistortionPolicy) -> Scene:
    json_path = scene_dir / "scene.json"
    meta = read_scene_json(json_path)
    layout = load_layout(
        scene_dir, name=name, dataset="synthetic", masks=masks, poses="sparse", distortion=distortion
    )
    traversals = {t.get("name"): (i, t) for i, t in enumerate(meta["traversals"]) if isinstance(t, dict)}
    cameras = {c.get("name"): (i, c) for i, c in enumerate(meta["cameras"]) if isinstance(c, dict)}
    entries: dict[str, Mapping[str, Any]] = {}
    for i, entry in enumerate(meta["frames"]):
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            raise DatasetError(f"frames[{i}] has no 'name'", json_path)
        if entry["name"] in entries:
            raise DatasetError(f"frames[{i}]: duplicate frame name {entry['name']!r}", json_path)
        entries[entry["name"]] = entry
    posed = {frame.name for frame in layout.frames}
    unposed = sorted(set(entries) - posed)
    if unposed:
        raise DatasetError(
            f"{len(unposed)} frames have no pose in the COLMAP model, e.g. {unposed[0]!r}", json_path
        )

    keyed = []
    for frame in layout.frames:
        entry = entries.get(frame.name)
        if entry is None:
            raise DatasetError(f"no entry for frame {frame.name!r}", json_path)
        keyed.append(_annotate(frame, entry, traversals, cameras, json_path))
    scene_meta = {
        key: meta.get(key)
        for key in (
            "seed",
            "preset",
            "units",
            "lane_width_m",
            "num_lanes",
            "world_up",
            "traversals",
            "cameras",
            "dynamic_objects",
        )
    }
    return replace(
        layout,
        frames=frames_by_key(keyed),
        metadata={**layout.metadata, **scene_meta, "scene_json": str(json_path)},
    )


def _annotate(
    frame: Frame,
    entry: Mapping[str, Any],
    traversals: Mapping[str, tuple[int, Any]],
    cameras: Mapping[str, tuple[int, Any]],
    json_path: Path,
) -> tuple[tuple[int, int, int, str], Frame]:
    where = f"frame {frame.name!r}"
    traversal, camera_name = entry.get("traversal"), entry.get("camera")
    if traversal not in traversals:
        raise DatasetError(f"{where}: traversal {traversal!r} is not declared in 'traversals'", json_path)
    if camera_name not in cameras:
        raise DatasetError(f"{where}: camera {camera_name!r} is not declared in 'cameras'", json_path)
    if entry.get("split") != frame.split:
        raise DatasetError(
            f"{where}: split {entry.get('split')!r} disagrees with the set files ({frame.split})", json_path
        )
    timestamp, index = entry.get("timestamp_us"), entry.get("index")
    for key, value in (("timestamp_us", timestamp), ("index", index)):
        if isinstance(value, bool) or not isinstance(value, int):
            raise DatasetError(f"{where}: '{key}' must be an integer, got {value!r}", json_path)
    camera_entry = cameras[camera_name][1]
    K = frame.camera.K
    for key, value in (("fx", K[0, 0]), ("fy", K[1, 1]), ("cx", K[0, 2]), ("cy", K[1, 2])):
        stated = camera_entry.get(key)
        if stated is not None and abs(float(stated) - value) > INTRINSICS_TOLERANCE:
            raise DatasetError(
                f"{where}: COLMAP {key}={value:g} but camera {camera_name!r} states {stated}", json_path
            )
    traversal_entry = traversals[traversal][1]
    metadata = {
        **frame.metadata,
        "lane_offset": traversal_entry.get("lane_offset"),
        "traversal_kind": traversal_entry.get("kind"),
        "index": index,
        "has_dynamic": bool(entry.get("has_dynamic", False)),
    }
    annotated = replace(
        frame, traversal=traversal, sensor=camera_name, timestamp_us=timestamp, metadata=metadata
    )
    return (traversals[traversal][0], cameras[camera_name][0], index, frame.name), annotated
