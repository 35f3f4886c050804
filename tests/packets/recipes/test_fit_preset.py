"""``prepare --fit --fit-preset NAME`` fits as the synthetic generator does (issue 41), so a recipe's degraded
fit differs from the scene's own fit only as the recipe says."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.runtime.threads import torch_threads

SCENE = "scene_0000_00"


@pytest.fixture(scope="module")
def world(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("world") / "synthetic"
    with torch_threads(1):
        assert main(["synth", "--preset", "tiny", "--out", str(root), "--no-progress"]) == 0
    return root


def prepare_tiny_fit(world: Path, out: Path) -> list[str]:
    """``prepare synthetic`` of ``world`` into ``out``, fitting each 3DGS with the tiny preset's configuration."""
    return ["prepare", "synthetic", "--root", str(world), "--fit", "--fit-preset", "tiny", "--out", str(out)]


def test_the_protocol_fit_made_by_prepare_is_the_generators_own(world: Path, tmp_path: Path) -> None:
    out = tmp_path / "store"
    with torch_threads(1):
        argv = prepare_tiny_fit(world, out)
        assert main([*argv, "--no-progress"]) == 0
    made = (out / "fits" / SCENE / "lane0.ply").read_bytes()
    assert made == (world / SCENE / "fits" / "lane0.ply").read_bytes()


def test_underfit_with_a_preset_stops_its_schedule(
    world: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import setdiff_bench.packets.fits as fits_module
    from setdiff_bench.synthetic.presets import get_preset

    seen = []
    fit = fits_module.fit_views_to_ply

    def spy(scene, views, config, out, **kwargs):
        seen.append((config, kwargs.get("stop_after")))
        return fit(scene, views, config, out, **kwargs)

    monkeypatch.setattr(fits_module, "fit_views_to_ply", spy)
    out = tmp_path / "store"
    with torch_threads(1):
        argv = prepare_tiny_fit(world, out)
        assert main([*argv, "--pairs", "underfit:0.5", "--no-progress"]) == 0
    preset = get_preset("tiny").fit
    # the preset's whole configuration (60 iterations, its densification and background points), stopped at 30
    assert seen == [(preset, 30)] and preset.iterations == 60
    assert (out / "fits" / SCENE / "lane0@underfit50.ply").is_file()
