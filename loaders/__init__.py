"""Dataset loaders (installed as ``setdiff_bench.loaders``): official on-disk layouts → :class:`Scene` objects.

The registry maps a dataset key to lazy ``"module:attr"`` specs, so listing datasets imports no
loader.  Every loader module provides::

    list_scenes(root, **options) -> list[str]                     # cheap: folder scan / one small table
    load_scenes(root, scenes=None, **options) -> list[Scene]      # full load, validated

A dataset whose single scene folder is recognised by its files also names a ``folder -> bool`` test in
:data:`SCENE_DETECTORS`; :func:`detect_dataset` asks them (``setdiff-bench fit --scene FOLDER``).

Usage::

    from setdiff_bench.loaders import load_scenes
    scenes = load_scenes("euvs", "/data/EUVS", scenes=["nuplan_vegas_location_1"], level=1)
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from setdiff_bench.errors import UsageError
from setdiff_bench.runtime.lazy import load_attribute

if TYPE_CHECKING:  # types imports torch; the registry stays light
    from setdiff_bench.types import Scene


@dataclass(frozen=True)
class DatasetSpec:
    """A dataset's loader functions as lazy ``"module:attr"`` specs, plus a one-line description."""

    key: str
    lister: str
    loader: str
    description: str

    def load_lister(self) -> Callable[..., list[str]]:
        return load_attribute(self.lister, f"dataset {self.key!r} lister")

    def load_loader(self) -> Callable[..., list[Scene]]:
        return load_attribute(self.loader, f"dataset {self.key!r} loader")


def _spec(key: str, description: str) -> DatasetSpec:
    module = f"setdiff_bench.loaders.{key}"
    return DatasetSpec(key, f"{module}:list_scenes", f"{module}:load_scenes", description)


DATASETS: dict[str, DatasetSpec] = {
    spec.key: spec
    for spec in (
        _spec("euvs", "EUVS: <scene>/{images, sparse/0, test_set.txt, dynamic_masks}, levels 1-3"),
        _spec("paralane", "Para-Lane: scene_<i>/clip_{0,1,2} parallel lanes, COLMAP text + lidar_poses.txt"),
        _spec("nuscenes", "nuScenes: v1.0-* JSON tables, every CAM_* keyframe and sweep in time order"),
        _spec("dl3dv", "DL3DV-10K: [<batch>/]<hash>/images_4 + colmap/sparse/0 or transforms.json"),
        _spec("synthetic", "setdiff-bench synthetic streets: EUVS layout + scene.json"),
        _spec("colmap", "any COLMAP scene: <scene>/sparse/0 + <scene>/images"),
        _spec("nerfstudio", "any nerfstudio scene: <scene>/transforms.json"),
    )
}


#: The datasets a single scene folder is recognised as by its own files, most specific layout first (a
#: synthetic scene is also an EUVS-layout folder; any folder with a COLMAP model is a colmap scene), each
#: with the ``"module:attr"`` of its loader module's ``folder -> bool`` test.
SCENE_DETECTORS: tuple[tuple[str, str], ...] = (
    ("synthetic", "setdiff_bench.loaders.synthetic:is_synthetic_scene"),
    ("euvs", "setdiff_bench.loaders.euvs:is_euvs_scene"),
    ("colmap", "setdiff_bench.loaders.colmap:is_colmap_scene"),
    ("nerfstudio", "setdiff_bench.loaders.nerfstudio:is_nerfstudio_scene"),
)


def detect_dataset(folder: str | os.PathLike[str]) -> str | None:
    """The first dataset of :data:`SCENE_DETECTORS` whose scene layout ``folder`` itself has, or ``None``."""
    path = Path(folder)
    for key, reference in SCENE_DETECTORS:
        if load_attribute(reference, f"dataset {key!r} scene test")(path):
            return key
    return None


def dataset_spec(dataset: str) -> DatasetSpec:
    """The registry entry of ``dataset``; ``UsageError`` listing the keys if unknown."""
    if dataset not in DATASETS:
        raise UsageError(f"unknown dataset {dataset!r}; available: {', '.join(DATASETS)}")
    return DATASETS[dataset]


def loader_options(dataset: str) -> dict[str, Any]:
    """The options ``load_scenes`` accepts for ``dataset``, with their defaults."""
    signature = inspect.signature(dataset_spec(dataset).load_loader())
    return {name: p.default for name, p in signature.parameters.items() if p.kind is p.KEYWORD_ONLY}


def _check_options(dataset: str, function: Callable[..., Any], options: dict[str, Any]) -> None:
    accepted = [n for n, p in inspect.signature(function).parameters.items() if p.kind is p.KEYWORD_ONLY]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise UsageError(
            f"{dataset} loader has no option {unknown[0]!r}; options: {', '.join(accepted) or 'none'}"
        )


def list_scenes(dataset: str, root: str | os.PathLike[str], **options: Any) -> list[str]:
    """Scene names of ``dataset`` under ``root`` (cheap: no image or pose is read).

    Options the lister does not take (e.g. ``masks`` for EUVS) are ignored, so the options of a
    ``load_scenes`` call can be passed unchanged.
    """
    spec = dataset_spec(dataset)
    lister = spec.load_lister()
    _check_options(dataset, spec.load_loader(), options)
    accepted = {n for n, p in inspect.signature(lister).parameters.items() if p.kind is p.KEYWORD_ONLY}
    return lister(root, **{k: v for k, v in options.items() if k in accepted})


def load_scenes(
    dataset: str, root: str | os.PathLike[str], scenes: Iterable[str] | None = None, **options: Any
) -> list[Scene]:
    """Load scenes of ``dataset`` from ``root`` in their official layout.

    Args:
        dataset: a key of :data:`DATASETS`.
        root: the dataset folder as downloaded (see docs/datasets.md).
        scenes: scene names (:func:`list_scenes`); ``None`` loads all.
        options: loader-specific keyword options (:func:`loader_options`).

    Returns:
        The scenes in the order requested (all: the lister's order), cameras in the project
        convention (OpenCV axes, world-to-camera).

    Raises:
        UsageError: unknown dataset or option.
        DatasetError / CameraError / ImageError: the data on disk is missing or inconsistent.
    """
    loader = dataset_spec(dataset).load_loader()
    _check_options(dataset, loader, options)
    return loader(root, scenes, **options)


__all__ = [
    "DATASETS",
    "SCENE_DETECTORS",
    "DatasetSpec",
    "dataset_spec",
    "detect_dataset",
    "list_scenes",
    "load_scenes",
    "loader_options",
]
