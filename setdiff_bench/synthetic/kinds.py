"""The synthetic world's scene kinds, declared as data: what ``synth`` (and anything else that makes or
reads synthetic scenes) needs to know about a kind without branching on it.

``driving``  multi-lane street drives in the EUVS layout plus ``scene.json`` (read by the ``synthetic``
             loader), ``scene_<seed>_<index>``, one fit ``fits/lane0.ply`` (:mod:`.generate`, :mod:`.presets`,
             :mod:`.driving_fit`).
``sparse``   handheld walks around a plaza in DL3DV's layout (read by the ``dl3dv`` loader),
             ``sparse_<seed>_<index>``, fits ``fits/n3.ply``, ``n6``, ``n9`` (:mod:`.sparse`).

A kind names its presets registry, preset lookup, generator and fitter as ``"module:attr"`` references,
as the dataset and method registries do (:mod:`setdiff_bench.runtime.lazy`); its generator and fitter are
a :class:`~setdiff_bench.synthetic.staging.SceneRecipe` and a :class:`~setdiff_bench.synthetic.fits.FitRecipe`,
the kind's steps declared as data in its own modules.  So importing this module imports neither torch nor
the generators: ``synth --help`` reads the presets' names from the registries' sources
(:func:`setdiff_bench.cli.declared.registry_names`) through :attr:`SceneKind.presets`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from setdiff_bench.errors import UsageError
from setdiff_bench.runtime.lazy import load_attribute

if TYPE_CHECKING:
    from setdiff_bench.synthetic.fits import FitRecipe
    from setdiff_bench.synthetic.staging import SceneRecipe


@dataclass(frozen=True)
class SceneKind:
    """One kind of synthetic scene.

    Attributes:
        name: the kind's key (``driving``, ``sparse``).
        dataset: the loader key its scenes are read with (:data:`setdiff_bench.loaders.DATASETS`).
        prefix: scene folders are named ``{prefix}_{seed:04d}_{index:02d}`` (:meth:`scene_name`).
        presets: ``"module:attr"`` of its presets registry, a dict literal keyed by preset name.
        lookup: ``"module:attr"`` of ``(name) -> preset``, a :class:`UsageError` listing the choices if unknown.
        generator: ``"module:attr"`` of how a scene is made, a
            :class:`~setdiff_bench.synthetic.staging.SceneRecipe` (its ``make`` generates one).
        fitter: ``"module:attr"`` of how a scene's 3DGS models are fitted, a
            :class:`~setdiff_bench.synthetic.fits.FitRecipe` (its ``keys`` and ``fit``).
    """

    name: str
    dataset: str
    prefix: str
    presets: str
    lookup: str
    generator: str
    fitter: str

    def scene_name(self, seed: int, index: int) -> str:
        """The folder name of scene ``index`` of ``seed``: ``{prefix}_{seed:04d}_{index:02d}``."""
        return f"{self.prefix}_{seed:04d}_{index:02d}"

    def preset_registry(self) -> Mapping[str, Any]:
        """The kind's presets by name (imports its presets module)."""
        return load_attribute(self.presets, f"scene kind {self.name!r} presets")

    def get_preset(self, name: str) -> Any:
        """The kind's preset called ``name``; :class:`UsageError` listing the kind's choices otherwise."""
        return load_attribute(self.lookup, f"scene kind {self.name!r} preset lookup")(name)

    def load_generator(self) -> SceneRecipe[Any, Any]:
        """How the kind's scenes are made (imports the generator, torch with it)."""
        return load_attribute(self.generator, f"scene kind {self.name!r} generator")

    def load_fitter(self) -> FitRecipe[Any]:
        """How the kind's 3DGS models are fitted (imports the fitter, torch with it)."""
        return load_attribute(self.fitter, f"scene kind {self.name!r} fitter")


SCENE_KINDS: dict[str, SceneKind] = {
    "driving": SceneKind(
        name="driving",
        dataset="synthetic",
        prefix="scene",
        presets="setdiff_bench.synthetic.presets:PRESETS",
        lookup="setdiff_bench.synthetic.presets:get_preset",
        generator="setdiff_bench.synthetic.generate:RECIPE",
        fitter="setdiff_bench.synthetic.driving_fit:FITTING",
    ),
    "sparse": SceneKind(
        name="sparse",
        dataset="dl3dv",
        prefix="sparse",
        presets="setdiff_bench.synthetic.sparse._sparse:SPARSE_PRESETS",  # read from source: its defining module
        lookup="setdiff_bench.synthetic.sparse:get_sparse_preset",
        generator="setdiff_bench.synthetic.sparse:RECIPE",
        fitter="setdiff_bench.synthetic.sparse:FITTING",
    ),
}


def scene_kind_of(preset_name: str) -> SceneKind:
    """The kind whose presets registry holds ``preset_name`` (imports the registries).

    Raises:
        UsageError: no kind has such a preset; lists every kind's presets.
    """
    names: list[str] = []
    for kind in SCENE_KINDS.values():
        registry = kind.preset_registry()
        if preset_name in registry:
            return kind
        names.extend(registry)
    raise UsageError(f"unknown preset {preset_name!r}; choose one of {', '.join(names)}", "--preset")
