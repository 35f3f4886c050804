"""The 3DGS fit: loss goes down on the tiny preset, masks are honoured, checkpoints resume exactly."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Sequence
from typing import Any

import numpy as np
import pytest
import torch

from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.gaussians.fit import (
    FitConfig,
    FitResult,
    FitView,
    fit_gaussians,
    initial_model,
    photometric_loss,
    scene_extent,
)
from setdiff_bench.gaussians.ply import read_ply, write_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.synthetic.presets import get_preset
from setdiff_bench.types import Scene


def _fit(scene: Scene, views: Sequence[FitView], config: FitConfig, **options: Any) -> FitResult:
    """``fit_gaussians`` of ``views`` from ``scene``'s sparse points and colours, without a progress bar."""
    return fit_gaussians(
        views, config, points=scene.points3d, colors=scene.points_rgb, progress=False, **options
    )


def masked_l1(model, views) -> float:
    """Mean L1 over the training views (masked pixels excluded), rendered independently of the fit loop."""
    errors = []
    with torch.no_grad():
        for view in views:
            pred = render(model, [view.camera], with_geometry=False).rgb[0]
            error = (pred - view.image).abs().mean(dim=0)
            keep = torch.ones_like(error, dtype=torch.bool) if view.mask is None else view.mask[0]
            errors.append(float(error[keep].mean()))
    return float(np.mean(errors))


def test_tiny_preset_fit_halves_the_l1_loss(tiny_scene, tiny_views, tmp_path):
    config = get_preset("tiny").fit
    assert config.iterations <= 60
    start = initial_model(tiny_views, tiny_scene.points3d, tiny_scene.points_rgb, config)
    result = _fit(tiny_scene, tiny_views, config)
    before, after = masked_l1(start, tiny_views), masked_l1(result.model, tiny_views)
    assert after <= 0.5 * before, (before, after)
    assert len(result.losses) == config.iterations and np.isfinite(result.losses).all()
    assert len(result.model) > len(start)  # densification grew the model
    assert result.model.sh_degree == config.sh_degree
    write_ply(tmp_path / "fit.ply", result.model)
    again = read_ply(tmp_path / "fit.ply")
    assert torch.equal(again.means, result.model.means) and torch.equal(again.sh, result.model.sh)


def test_scene_extent_is_the_inria_camera_radius(tiny_views):
    centers = np.stack([v.camera.center for v in tiny_views])
    center, radius = scene_extent(tiny_views)
    assert np.allclose(center, centers.mean(axis=0))
    assert radius == pytest.approx(1.1 * np.linalg.norm(centers - centers.mean(axis=0), axis=1).max())


def test_random_initialisation_fills_the_camera_box(tiny_views):
    config = FitConfig(random_init_points=500, sh_degree=1)
    model = initial_model(tiny_views, None, None, config)
    centers = np.stack([v.camera.center for v in tiny_views])
    _, radius = scene_extent(tiny_views)
    means = model.means.numpy()
    assert len(model) == 500 and model.sh_degree == 1
    assert (means >= centers.min(axis=0) - radius - 1e-4).all() and (
        means <= centers.max(axis=0) + radius + 1e-4
    ).all()
    assert np.allclose(model.opacities.numpy(), 0.1, atol=1e-6)
    assert torch.equal(initial_model(tiny_views, None, None, config).means, model.means)  # seeded


def test_masked_pixels_add_no_loss_and_no_gradient():
    target = torch.rand(1, 3, 24, 32)
    pred = torch.rand(1, 3, 24, 32, requires_grad=True)
    mask = torch.zeros(1, 1, 24, 32, dtype=torch.bool)
    mask[..., :, :16] = True
    loss, l1 = photometric_loss(pred, target, mask, 0.2)
    loss.backward()
    assert pred.grad[..., 16:].abs().max() == 0 and pred.grad[..., :16].abs().max() > 0
    # L1 over all pixels with the masked half counted as zero error (hand-derived)
    expected = float((pred.detach() - target).abs()[..., :16].sum() / pred.numel())
    assert float(l1.detach()) == pytest.approx(expected, rel=1e-5)
    clean = target.clone().requires_grad_(True)
    zero, _ = photometric_loss(clean, target, None, 0.2)
    assert float(zero.detach()) == pytest.approx(0.0, abs=1e-6)


def _short_config() -> FitConfig:
    return FitConfig.schedule(16, densify_every=4, opacity_reset_every=10, tile_size=8, seed=3)


def test_resume_gives_the_uninterrupted_result(tiny_scene, tiny_views, tmp_path):
    config = _short_config()
    straight = _fit(tiny_scene, tiny_views, config)
    assert straight.events and any(e["split"] + e["cloned"] > 0 for e in straight.events)
    partial = _fit(tiny_scene, tiny_views, config, checkpoint_dir=tmp_path / "ckpt", stop_after=7)
    assert len(partial.losses) == 7
    resumed = _fit(tiny_scene, tiny_views, config, checkpoint_dir=tmp_path / "ckpt")
    assert resumed.start_iteration == 8 and len(resumed.losses) == 9
    assert partial.losses + resumed.losses == straight.losses
    for name, value in straight.model.tensors().items():
        assert torch.equal(value, resumed.model.tensors()[name]), name


def test_checkpoint_of_another_configuration_is_refused(tiny_scene, tiny_views, tmp_path):
    config = _short_config()
    _fit(tiny_scene, tiny_views[:2], config, checkpoint_dir=tmp_path, stop_after=2)
    with pytest.raises(CheckpointError, match="different fit configuration"):
        _fit(
            tiny_scene, tiny_views[:2], dataclasses.replace(config, lr_opacity=0.01), checkpoint_dir=tmp_path
        )
    with pytest.raises(CheckpointError, match="different training frames"):
        _fit(tiny_scene, tiny_views[1:], config, checkpoint_dir=tmp_path)
    (tmp_path / "fit_state.safetensors").write_bytes(b"garbage")
    with pytest.raises(CheckpointError, match="does not match"):
        _fit(tiny_scene, tiny_views[:2], config, checkpoint_dir=tmp_path)


def flat_json(config: FitConfig) -> dict[str, object]:
    """``config`` in the JSON shape of fits written before the strategy object: every setting top level."""
    data = config.to_json()
    return {**{k: v for k, v in data.items() if k != "strategy"}, **data["strategy"]}


def test_fit_config_json_round_trips_in_both_shapes():
    config = FitConfig.schedule(
        120, densify_every=6, max_gaussians=500, min_opacity=0.01, tile_size=16, seed=4
    )
    assert config.strategy.max_gaussians == 500 and config.strategy.min_opacity == 0.01  # flat overrides
    assert config.strategy.densify_from == 12 and config.sh_increase_every == 12 and config.tile_size == 16
    assert FitConfig.from_json(json.loads(json.dumps(config.to_json()))) == config
    assert FitConfig.from_json(flat_json(config)) == config
    for bad in ({"densify_evry": 3}, {"strategy": {"lr_means": 1.0}}, {"strategy": 3}):
        with pytest.raises(UsageError) as error:
            FitConfig.from_json(bad)
        assert len(str(error.value).splitlines()) == 1
    with pytest.raises(UsageError, match="densify_evry"):
        FitConfig.schedule(10, densify_every=1, densify_evry=3)


def test_checkpoint_with_the_old_flat_configuration_resumes(tiny_scene, tiny_views, tmp_path):
    config = _short_config()
    straight = _fit(tiny_scene, tiny_views[:3], config)
    _fit(tiny_scene, tiny_views[:3], config, checkpoint_dir=tmp_path, stop_after=5)
    state_path = tmp_path / "fit_state.json"
    state = json.loads(state_path.read_text())
    state["config"] = flat_json(config)
    state_path.write_text(json.dumps(state))
    resumed = _fit(tiny_scene, tiny_views[:3], config, checkpoint_dir=tmp_path)
    assert resumed.start_iteration == 6
    for name, value in straight.model.tensors().items():
        assert torch.equal(value, resumed.model.tensors()[name]), name


def test_views_without_any_visible_gaussian_do_not_crash(tiny_views):
    view = tiny_views[0]
    behind = view.camera.center - 50.0 * view.camera.view_direction  # points behind the camera only
    points = behind[None] + np.random.default_rng(0).normal(size=(20, 3))
    config = FitConfig.schedule(3, densify_every=1, tile_size=8)
    result = fit_gaussians(
        [FitView(view.name, view.camera, view.image, None)],
        config,
        points=points,
        colors=None,
        progress=False,
    )
    assert len(result.losses) == 3
