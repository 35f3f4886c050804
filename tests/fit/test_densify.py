"""Adaptive density control and the optimiser plumbing, against hand-derived expectations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera, intrinsics_matrix, look_at
from setdiff_bench.gaussians.densify import DensityStats, densify_and_prune, reset_opacity
from setdiff_bench.gaussians.fit import photometric_loss
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.optim import GaussianParameters, exponential_lr
from setdiff_bench.gaussians.render import render

RATES = {"means": 1e-2, "sh_dc": 1e-2, "sh_rest": 1e-3, "opacity_logits": 5e-2, "log_scales": 5e-3, "quats": 1e-3}


def model_of(means, log_scale: float, opacity: float = 0.8) -> GaussianModel:
    means = torch.as_tensor(np.asarray(means, np.float32))
    n = means.shape[0]
    quats = torch.zeros(n, 4)
    quats[:, 0] = 1.0
    return GaussianModel(means, quats, torch.full((n, 3), log_scale), torch.full((n,), math.log(opacity / (1 - opacity))),
                         torch.zeros(n, 4, 3))


def test_clone_small_split_large_and_prune_transparent():
    means = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]
    model = model_of(means, math.log(0.05))
    model.log_scales[2:] = math.log(1.0)          # rows 2, 3 are large (> percent_dense · extent = 0.1)
    model.opacity_logits[3] = math.log(0.001 / 0.999)  # row 3 is nearly transparent → pruned
    params = GaussianParameters(model, RATES)
    stats = DensityStats.zeros(4)
    stats.grad_sum[:] = torch.tensor([5e-4, 1e-5, 5e-4, 1e-5])
    stats.count[:] = 1
    result = densify_and_prune(params, stats, grad_threshold=2e-4, percent_dense=0.01, extent=10.0,
                               min_opacity=0.005, max_screen_size=None, max_world_fraction=0.1,
                               generator=torch.Generator().manual_seed(0))
    assert (result.cloned, result.split, result.pruned) == (1, 1, 1)
    out = params.model().detach()
    assert len(out) == 5 == result.total  # 0, 1, clone of 0, two samples of 2 (2 and 3 removed)
    assert torch.equal(out.means[:2], model.means[:2]) and torch.equal(out.means[2], model.means[0])
    samples = out.means[3:]
    assert ((samples - model.means[2]).norm(dim=1) < 4.0).all()   # drawn from N(mean, 1 m²)
    assert not torch.equal(samples[0], samples[1])
    assert torch.allclose(out.log_scales[3:], torch.full((2, 3), math.log(1.0 / 1.6)))


def test_adam_moments_follow_their_rows():
    params = GaussianParameters(model_of([[0, 0, 0], [1, 0, 0], [2, 0, 0]], -2.0), RATES)
    model = params.model()
    (model.means.sum() * torch.tensor(1.0)).backward()
    params.optimizer.step()
    moments = params.optimizer.state[params.params["means"]]["exp_avg"].clone()
    params.remap(torch.tensor([2, 0, -1]), {"means": torch.tensor([[2.0, 0, 0], [0.0, 0, 0], [9.0, 9, 9]]),
                                            **{k: v.detach()[torch.tensor([2, 0, 0])] for k, v in params.params.items()
                                               if k != "means"}})
    state = params.optimizer.state[params.params["means"]]
    assert torch.equal(state["exp_avg"][0], moments[2]) and torch.equal(state["exp_avg"][1], moments[0])
    assert torch.equal(state["exp_avg"][2], torch.zeros(3)) and torch.equal(state["exp_avg_sq"][2], torch.zeros(3))
    assert torch.equal(params.params["means"][2].detach(), torch.tensor([9.0, 9, 9]))
    assert params.optimizer.param_groups[0]["params"][0] is params.params["means"]


def test_opacity_reset_caps_at_one_percent_and_zeroes_moments():
    params = GaussianParameters(model_of([[0, 0, 0], [1, 0, 0]], -2.0, opacity=0.9), RATES)
    params.params["opacity_logits"].data[1] = math.log(0.005 / 0.995)
    params.model().opacity_logits.sum().backward()
    params.optimizer.step()
    reset_opacity(params)
    opacity = torch.sigmoid(params.params["opacity_logits"].detach())
    assert opacity[0].item() == pytest.approx(0.01, rel=1e-5)
    assert opacity[1].item() < 0.01  # already below: unchanged
    assert params.optimizer.state[params.params["opacity_logits"]]["exp_avg"].abs().max() == 0


def test_exponential_learning_rate_matches_inria():
    assert exponential_lr(0, 1e-2, 1e-4, 100) == pytest.approx(1e-2)
    assert exponential_lr(100, 1e-2, 1e-4, 100) == pytest.approx(1e-4)
    assert exponential_lr(50, 1e-2, 1e-4, 100) == pytest.approx(1e-3)  # geometric midpoint
    assert exponential_lr(200, 1e-2, 1e-4, 100) == pytest.approx(1e-4)
    # delayed start: cosine ramp from delay_mult
    assert exponential_lr(0, 1e-2, 1e-4, 100, delay_steps=10, delay_mult=0.1) == pytest.approx(1e-3)


def test_densification_adds_gaussians_where_the_gradient_is_large():
    """A plane of grey Gaussians in front of a camera; the target is its render plus a bright square on the right.
    Only Gaussians covering the square get large view-space gradients, and only there are Gaussians added."""
    width, height = 48, 32
    camera = Camera(intrinsics_matrix(40.0, 40.0, 24.0, 16.0), look_at([0, 0, 0], [0, 0, 1], up=(0, -1, 0)),
                    width, height)
    xs, ys = np.meshgrid(np.linspace(-0.6, 0.6, 13), np.linspace(-0.4, 0.4, 9))
    means = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, 1.0)], axis=1)
    model = model_of(means, math.log(0.06), opacity=0.9)
    params = GaussianParameters(model, RATES)
    with torch.no_grad():
        target = render(model, [camera], with_geometry=False).rgb  # the model's own image …
    target[..., 8:24, 30:44] = 1.0  # … plus a bright square it cannot yet explain
    stats = DensityStats.zeros(len(params))
    out = render(params.model(), [camera], with_geometry=False)
    loss, _ = photometric_loss(out.rgb, target, None, 0.2)
    loss.backward()
    stats.accumulate(out.meta[0], width, height)
    grads = stats.mean_grad()
    uv, _ = camera.project(means)
    near_square = uv[:, 0] > 20  # the square spans u 30–44; SSIM's 11-px window reaches ~6 px beyond
    threshold = float(grads.max()) * 0.2
    assert near_square[(grads > threshold).numpy()].all()
    assert not near_square.all() and (grads[torch.from_numpy(~near_square)] < threshold).all()
    result = densify_and_prune(params, stats, grad_threshold=threshold, percent_dense=0.1, extent=1.0,
                               min_opacity=0.005, max_screen_size=None, max_world_fraction=10.0,
                               generator=torch.Generator().manual_seed(0))
    added = params.model().means.detach()[len(means):].numpy()
    assert result.cloned + result.split > 0 and len(added) == result.cloned + result.split
    new_uv, _ = camera.project(added)
    assert (new_uv[:, 0] > 18).all()  # all new Gaussians sit on the bright square's side
