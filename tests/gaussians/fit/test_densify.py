"""Adaptive density control and the optimiser plumbing, against hand-derived expectations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.gaussians.densify import DensificationStrategy, reset_opacity
from setdiff_bench.gaussians.fit import photometric_loss
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.optim import GaussianParameters, exponential_lr
from setdiff_bench.gaussians.render import render
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at

RATES = {
    "means": 1e-2,
    "sh_dc": 1e-2,
    "sh_rest": 1e-3,
    "opacity_logits": 5e-2,
    "log_scales": 5e-3,
    "quats": 1e-3,
}


def model_of(means, log_scale: float, opacity: float = 0.8) -> GaussianModel:
    means = torch.as_tensor(np.asarray(means, np.float32))
    n = means.shape[0]
    quats = torch.zeros(n, 4)
    quats[:, 0] = 1.0
    return GaussianModel(
        means,
        quats,
        torch.full((n, 3), log_scale),
        torch.full((n,), math.log(opacity / (1 - opacity))),
        torch.zeros(n, 4, 3),
    )


def test_clone_small_split_large_and_prune_transparent():
    means = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]
    model = model_of(means, math.log(0.05))
    model.log_scales[2:] = math.log(1.0)  # rows 2, 3 are large (> percent_dense · extent = 0.1)
    model.opacity_logits[3] = math.log(0.001 / 0.999)  # row 3 is nearly transparent → pruned
    params = GaussianParameters(model, RATES)
    strategy = DensificationStrategy(grad_threshold=2e-4, percent_dense=0.01, min_opacity=0.005)
    state = strategy.initialize_state(4, extent=10.0, generator=torch.Generator().manual_seed(0))
    state.stats.grad_sum[:] = torch.tensor([5e-4, 1e-5, 5e-4, 1e-5])
    state.stats.count[:] = 1
    result = strategy.densify_and_prune(params, state, prune_large=False)
    assert (result.cloned, result.split, result.pruned) == (1, 1, 1)
    assert torch.equal(state.stats.count, torch.zeros(5))  # the statistics restart for the new rows
    out = params.model().detach()
    assert len(out) == 5 == result.total  # 0, 1, clone of 0, two samples of 2 (2 and 3 removed)
    assert torch.equal(out.means[:2], model.means[:2]) and torch.equal(out.means[2], model.means[0])
    samples = out.means[3:]
    assert ((samples - model.means[2]).norm(dim=1) < 4.0).all()  # drawn from N(mean, 1 m²)
    assert not torch.equal(samples[0], samples[1])
    assert torch.allclose(out.log_scales[3:], torch.full((2, 3), math.log(1.0 / 1.6)))


def test_adam_moments_follow_their_rows():
    params = GaussianParameters(model_of([[0, 0, 0], [1, 0, 0], [2, 0, 0]], -2.0), RATES)
    model = params.model()
    (model.means.sum() * torch.tensor(1.0)).backward()
    params.optimizer.step()
    moments = params.optimizer.state[params.params["means"]]["exp_avg"].clone()
    params.remap(
        torch.tensor([2, 0, -1]),
        {
            "means": torch.tensor([[2.0, 0, 0], [0.0, 0, 0], [9.0, 9, 9]]),
            **{k: v.detach()[torch.tensor([2, 0, 0])] for k, v in params.params.items() if k != "means"},
        },
    )
    state = params.optimizer.state[params.params["means"]]
    assert torch.equal(state["exp_avg"][0], moments[2]) and torch.equal(state["exp_avg"][1], moments[0])
    assert torch.equal(state["exp_avg"][2], torch.zeros(3)) and torch.equal(
        state["exp_avg_sq"][2], torch.zeros(3)
    )
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


def meta_grads(meta, width: int, height: int) -> torch.Tensor:
    """``(N,)`` mean view-space gradient norms of one render's ``meta`` (the strategy's statistics)."""
    state = DensificationStrategy().initialize_state(
        len(meta["visible"]), extent=1.0, generator=torch.Generator()
    )
    state.stats.accumulate(meta, width, height)
    return state.stats.mean_grad()


def test_densification_adds_gaussians_where_the_gradient_is_large():
    """A plane of grey Gaussians in front of a camera; the target is its render plus a bright square on the right.
    Only Gaussians covering the square get large view-space gradients, and only there are Gaussians added."""
    width, height = 48, 32
    camera = Camera(
        intrinsics_matrix(40.0, 40.0, 24.0, 16.0), look_at([0, 0, 0], [0, 0, 1], up=(0, -1, 0)), width, height
    )
    xs, ys = np.meshgrid(np.linspace(-0.6, 0.6, 13), np.linspace(-0.4, 0.4, 9))
    means = np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, 1.0)], axis=1)
    model = model_of(means, math.log(0.06), opacity=0.9)
    params = GaussianParameters(model, RATES)
    with torch.no_grad():
        target = render(model, [camera], with_geometry=False).rgb  # the model's own image …
    target[..., 8:24, 30:44] = 1.0  # … plus a bright square it cannot yet explain
    out = render(params.model(), [camera], with_geometry=False)
    loss, _ = photometric_loss(out.rgb, target, None, 0.2)
    loss.backward()
    grads = meta_grads(out.meta[0], width, height)
    uv, _ = camera.project(means)
    near_square = uv[:, 0] > 20  # the square spans u 30–44; SSIM's 11-px window reaches ~6 px beyond
    threshold = float(grads.max()) * 0.2
    assert near_square[(grads > threshold).numpy()].all()
    assert not near_square.all() and (grads[torch.from_numpy(~near_square)] < threshold).all()
    strategy = DensificationStrategy(grad_threshold=threshold, percent_dense=0.1, max_world_fraction=10.0)
    state = strategy.initialize_state(len(params), extent=1.0, generator=torch.Generator().manual_seed(0))
    state.stats.accumulate(out.meta[0], width, height)
    result = strategy.densify_and_prune(params, state, prune_large=False)
    added = params.model().means.detach()[len(means) :].numpy()
    assert result.cloned + result.split > 0 and len(added) == result.cloned + result.split
    new_uv, _ = camera.project(added)
    assert (new_uv[:, 0] > 18).all()  # all new Gaussians sit on the bright square's side


def hand_meta(pixel_grads, radius: float = 1.0, big: int | None = None) -> dict[str, torch.Tensor]:
    """A render's per-camera ``meta`` built by hand: every Gaussian visible, ``means2d.grad`` = ``pixel_grads``,
    screen radius ``radius`` (30 px for row ``big``)."""
    grads = torch.tensor(pixel_grads, dtype=torch.float32)
    means2d = torch.zeros_like(grads, requires_grad=True)
    means2d.grad = grads
    radii = torch.full((len(grads), 2), radius)
    if big is not None:
        radii[big] = 30.0
    return {"means2d": means2d, "radii": radii, "visible": torch.ones(len(grads), dtype=torch.bool)}


def test_strategy_state_evolves_on_its_schedule():
    """Four Gaussians through ``step_post_backward`` on a 2×2-pixel view (so NDC gradients equal pixel
    gradients), thresholds chosen so that every count below follows by hand from the module docstring."""
    model = model_of([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], math.log(0.05))
    model.log_scales[1] = math.log(1.0)  # row 1 is large: 1.0 > percent_dense · extent = 0.1
    model.opacity_logits[3] = math.log(0.001 / 0.999)  # row 3 is below min_opacity 0.005
    params = GaussianParameters(model, RATES)
    strategy = DensificationStrategy(
        densify_from=1,
        densify_until=10,
        densify_every=2,
        opacity_reset_every=4,
        grad_threshold=1e-3,
        percent_dense=0.01,
        min_opacity=0.005,
    )
    state = strategy.initialize_state(4, extent=10.0, generator=torch.Generator().manual_seed(0))
    strong = [[2e-3, 0.0], [0.0, 3e-3], [1e-4, 0.0], [0.0, 0.0]]  # norms 2e-3, 3e-3 (≥ 1e-3), 1e-4, 0

    # step 1 ≤ densify_from: statistics only
    assert strategy.step_post_backward(params, state, 1, hand_meta(strong), 2, 2) is None
    assert torch.equal(state.stats.count, torch.ones(4))
    assert torch.allclose(state.stats.grad_sum, torch.tensor([2e-3, 3e-3, 1e-4, 0.0]))
    # step 2: the mean gradient over both views selects rows 0 (small: cloned) and 1 (large: split in two);
    # row 3 is pruned for its opacity, row 1 replaced by its samples: 4 + 1 + 2 − 1 − 1 = 5 Gaussians
    result = strategy.step_post_backward(params, state, 2, hand_meta(strong), 2, 2)
    assert (result.cloned, result.split, result.pruned, result.total) == (1, 1, 1, 5)
    assert len(params) == 5 and torch.equal(state.stats.count, torch.zeros(5))
    opacity = torch.sigmoid(params.params["opacity_logits"].detach())
    assert torch.allclose(opacity, torch.full((5,), 0.8))  # row 3 is gone
    quiet = [[0.0, 0.0]] * 5
    # step 3 is no densification step; step 4 densifies nothing (no gradient), prunes nothing (row 0's
    # 30-px screen radius counts only after the first reset, i.e. from step 5), then resets every opacity
    # to 0.01
    assert strategy.step_post_backward(params, state, 3, hand_meta(quiet), 2, 2) is None
    result = strategy.step_post_backward(params, state, 4, hand_meta(quiet, big=0), 2, 2)
    assert (result.cloned, result.split, result.pruned, result.total) == (0, 0, 0, 5)
    assert torch.allclose(torch.sigmoid(params.params["opacity_logits"].detach()), torch.full((5,), 0.01))
    # step 6 (> the first reset): row 2's screen radius of 30 px exceeds max_screen_size 20 → pruned;
    # the split samples' scale 1 / 1.6 stays below max_world_fraction · extent = 1
    strategy.step_post_backward(params, state, 5, hand_meta(quiet), 2, 2)
    result = strategy.step_post_backward(params, state, 6, hand_meta(quiet, big=2), 2, 2)
    assert (result.cloned, result.split, result.pruned, result.total) == (0, 0, 1, 4)
    # from densify_until on, the strategy does nothing
    before = {k: v.detach().clone() for k, v in params.params.items()}
    assert strategy.step_post_backward(params, state, 10, hand_meta(strong[:4]), 2, 2) is None
    assert torch.equal(state.stats.count, torch.zeros(4))
    assert all(torch.equal(before[k], v.detach()) for k, v in params.params.items())


def test_strategy_schedule_compresses_the_standard_one():
    strategy = DensificationStrategy.schedule(1000, densify_every=50, max_gaussians=9)
    assert (strategy.densify_from, strategy.densify_until, strategy.densify_every) == (100, 600, 50)
    assert strategy.opacity_reset_every == 300 and strategy.max_gaussians == 9
    assert strategy.grad_threshold == DensificationStrategy().grad_threshold == 2e-4
