"""Issue 37: the synthetic world's scene kinds declared as data (``synthetic/kinds.py``), the staging every
generator shares (``synthetic/staging.py``) and the fit loop every fitter shares (``synthetic/fits.py``)."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from setdiff_bench.cli.declared import registry_names
from setdiff_bench.errors import UsageError
from setdiff_bench.synthetic.fits import FitRecipe
from setdiff_bench.synthetic.generate import scene_name
from setdiff_bench.synthetic.kinds import SCENE_KINDS, scene_kind_of
from setdiff_bench.synthetic.presets import PRESETS
from setdiff_bench.synthetic.sparse import SPARSE_PRESETS, sparse_scene_name
from setdiff_bench.synthetic.staging import SceneRecipe


def test_every_preset_has_one_kind() -> None:
    assert [scene_kind_of(name).name for name in PRESETS] == ["driving"] * len(PRESETS)
    assert [scene_kind_of(name).name for name in SPARSE_PRESETS] == ["sparse"] * len(SPARSE_PRESETS)
    assert not set(PRESETS) & set(SPARSE_PRESETS)
    with pytest.raises(
        UsageError, match="unknown preset 'nope'; choose one of tiny, default, large, sparse_tiny"
    ):
        scene_kind_of("nope")


def test_kind_specs_agree_with_their_modules() -> None:
    driving, sparse = SCENE_KINDS["driving"], SCENE_KINDS["sparse"]
    assert (driving.dataset, sparse.dataset) == ("synthetic", "dl3dv")
    assert driving.scene_name(3, 1) == scene_name(3, 1) == "scene_0003_01"
    assert sparse.scene_name(3, 1) == sparse_scene_name(3, 1) == "sparse_0003_01"
    for kind in SCENE_KINDS.values():
        # synth --help reads the names from source; a run imports the registry: the same presets
        assert registry_names(*kind.presets.split(":")) == tuple(kind.preset_registry())
        for name, preset in kind.preset_registry().items():
            assert kind.get_preset(name) is preset
        generator, fitter = kind.load_generator(), kind.load_fitter()
        assert isinstance(generator, SceneRecipe) and isinstance(fitter, FitRecipe)
        assert generator.name(0, 2) == kind.scene_name(0, 2)
    assert driving.load_fitter().keys(PRESETS["tiny"]) == ("lane0",)
    assert sparse.load_fitter().keys(SPARSE_PRESETS["sparse_tiny"]) == ("n3", "n6", "n9")
    assert sparse.load_fitter().keys(replace(SPARSE_PRESETS["sparse_tiny"], views=(6,))) == ("n6",)
    with pytest.raises(UsageError, match="unknown sparse preset"):
        sparse.get_preset("tiny")


def test_kinds_module_imports_no_torch() -> None:
    probe = "import sys, setdiff_bench.synthetic.kinds; print('torch' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "False"


def _fake_recipe(calls: list[str]) -> SceneRecipe:
    """A recipe whose steps only record themselves and write ``scene.json`` naming the preset."""

    def build(preset: Any, seed: int, index: int) -> str:
        calls.append("build")
        return preset.name

    def render(build: str, progress: object, device: object) -> list[str]:
        calls.append("render")
        return ["frame"]

    def write(build: str, frames: object, folder: Path) -> None:
        (folder / "scene.json").write_text(json.dumps({"preset": build}), encoding="utf-8")

    return SceneRecipe(lambda seed, index: f"fake_{seed}_{index}", build, render, write)


def test_recipe_keeps_a_complete_scene_unless_overwrite(tmp_path: Path) -> None:
    calls: list[str] = []
    recipe = _fake_recipe(calls)
    tiny = PRESETS["tiny"]
    folder = recipe.make(tmp_path / "out", tiny, 1, 2)
    assert folder == tmp_path / "out" / "fake_1_2" and calls == ["build", "render"]
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["fake_1_2"]  # no staging folder left
    assert recipe.make(tmp_path / "out", tiny, 1, 2) == folder and calls == ["build", "render"]
    with pytest.raises(UsageError, match="scene exists with preset 'tiny', not 'default'; pass --overwrite"):
        recipe.make(tmp_path / "out", PRESETS["default"], 1, 2)
    recipe.make(tmp_path / "out", PRESETS["default"], 1, 2, overwrite=True)
    assert calls == ["build", "render"] * 2
    assert json.loads((folder / "scene.json").read_text(encoding="utf-8")) == {"preset": "default"}


def test_fits_present_are_kept(tmp_path: Path) -> None:
    scene = tmp_path / "sparse_0000_00"
    (scene / "fits").mkdir(parents=True)
    for key in ("n3", "n6", "n9"):
        (scene / "fits" / f"{key}.ply").write_bytes(b"")
    lines = SCENE_KINDS["sparse"].load_fitter().fit(scene, SPARSE_PRESETS["sparse_tiny"])
    assert lines == ["n3 already present", "n6 already present", "n9 already present"]
    (scene / "fits" / "lane0.ply").write_bytes(b"")
    assert SCENE_KINDS["driving"].load_fitter().fit(scene, PRESETS["tiny"]) == ["fit already present"]
