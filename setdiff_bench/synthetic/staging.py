"""How a synthetic scene kind makes a scene, declared as data (:class:`SceneRecipe`: its name, build, render
and write steps), and what every kind does around those steps (:meth:`SceneRecipe.make`): keep a complete
scene (its ``scene.json`` names the same preset) unless ``overwrite``, and write a new one in a staging
folder renamed into place only when every file is written, so an interrupted run never leaves a
half-written scene.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import staged_folder

Build = TypeVar("Build")
Preset = TypeVar("Preset", bound="NamedPreset")


class NamedPreset(Protocol):
    """A preset: all :meth:`SceneRecipe.make` reads of it is its name (written to ``scene.json``)."""

    @property
    def name(self) -> str: ...


def scene_header(format_tag: str, name: str, seed: int, index: int, preset_name: str) -> dict[str, object]:
    """The keys every kind's ``scene.json`` opens with: its format tag, the scene's name, ``(seed, index)`` and
    preset (docs/synthetic_format.md); a kind adds its own keys."""
    return {"format": format_tag, "scene": name, "seed": seed, "index": index, "preset": preset_name}


def complete_scene(final: Path, preset_name: str) -> bool:
    """Whether ``final`` holds a complete scene (its ``scene.json`` written last).

    Raises:
        UsageError: the complete scene was generated with another preset than ``preset_name``.
    """
    if not (final / "scene.json").is_file():
        return False
    try:
        existing = json.loads((final / "scene.json").read_text(encoding="utf-8")).get("preset")
    except (OSError, json.JSONDecodeError, AttributeError):
        existing = None
    if existing != preset_name:
        raise UsageError(
            f"scene exists with preset {existing!r}, not {preset_name!r}; pass --overwrite to regenerate it",
            final / "scene.json",
        )
    return True


@dataclass(frozen=True)
class SceneRecipe(Generic[Preset, Build]):
    """How one scene kind makes a scene, step by step; :meth:`make` does what every kind does around them.

    Attributes:
        name: ``(seed, index) -> folder name``.
        build: ``(preset, seed, index) -> the scene in memory``.
        render: ``(build, progress, device) -> frames``; ``progress(done, total)`` receives rendered frames.
        write: ``(build, frames, folder)``: every file of the scene into an empty folder.
    """

    name: Callable[[int, int], str]
    build: Callable[[Preset, int, int], Build]
    render: Callable[[Build, Callable[[int, int], None] | None, Any], Sequence[Any]]
    write: Callable[[Build, Any, Path], None]

    def make(
        self,
        out_root: str | os.PathLike[str],
        preset: Preset,
        seed: int,
        index: int,
        *,
        overwrite: bool = False,
        progress: Callable[[int, int], None] | None = None,
        device: Any = "cpu",
    ) -> Path:
        """Generate scene ``index`` of ``seed`` under ``out_root``; returns its folder.

        A complete existing scene is kept unless ``overwrite`` (:func:`complete_scene`); otherwise the scene is
        built, rendered on ``device`` (the ground-truth rasteriser is pure PyTorch: a GPU for the large
        presets) and written in a staging folder renamed into place when complete.  Files are byte-identical
        for the same ``(preset, seed, index)``, device type, torch build and thread count.
        """
        root = Path(out_root)
        final = root / self.name(seed, index)
        if not overwrite and complete_scene(final, preset.name):
            return final
        root.mkdir(parents=True, exist_ok=True)
        scene = self.build(preset, seed, index)
        frames = self.render(scene, progress, device)
        with staged_folder(final) as staging:
            self.write(scene, frames, staging)
        return final
