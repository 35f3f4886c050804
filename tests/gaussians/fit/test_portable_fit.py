"""A scene fit gives the same bits on every x86-64 CPU and for any thread count (gaussians/portable.py).

The portable pieces are checked against torch's own operators (same values to float rounding), and a
short fit with densification is run in subprocesses under other ATen instruction sets
(``ATEN_CPU_CAPABILITY``), another oneDNN ISA and another thread count: the PLYs must be byte-identical.
Before the portable arithmetic, the default / AVX2 / AVX-512 runs of the same fit gave three different
PLYs on the CI machine.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from setdiff_bench.gaussians.optim import PortableAdam
from setdiff_bench.gaussians.portable import logistic, normalize, standard_normal, vector_norm
from setdiff_bench.metrics.gaussian_filter import blur_exact, blur_torch
from setdiff_bench.metrics.ssim import ssim


def _random(*shape: int, seed: int = 0, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    # torch.rand's uniform draws are scalar, so inputs are the same under any capability
    return torch.rand(*shape, generator=torch.Generator().manual_seed(seed), dtype=torch.float64).to(dtype)


def test_logistic_norm_and_normalize_equal_torch_to_rounding():
    x = _random(4096, 4) * 40 - 20
    assert torch.allclose(logistic(x), torch.sigmoid(x), rtol=5e-7, atol=1e-30)
    assert torch.allclose(vector_norm(x), torch.linalg.vector_norm(x, dim=-1), rtol=3e-7, atol=0)
    assert torch.allclose(normalize(x), torch.nn.functional.normalize(x, dim=-1), rtol=0, atol=3e-7)
    assert torch.equal(normalize(torch.zeros(2, 3)), torch.zeros(2, 3))  # eps guards the zero vector


def test_logistic_gradient_is_sigmoid_derivative():
    x = (_random(257) * 16 - 8).requires_grad_()
    logistic(x).sum().backward()
    exact = torch.exp(-x.detach().double()) / (1 + torch.exp(-x.detach().double())) ** 2  # σ' in float64
    assert torch.allclose(x.grad.double(), exact, rtol=2e-6, atol=0)


def test_standard_normal_follows_the_generator_and_is_normal():
    a = standard_normal(20000, 3, torch.Generator().manual_seed(1))
    b = standard_normal(20000, 3, torch.Generator().manual_seed(1))
    c = standard_normal(20000, 3, torch.Generator().manual_seed(2))
    assert a.shape == (20000, 3) and a.dtype == torch.float32
    assert torch.equal(a, b) and not torch.equal(a, c)
    assert abs(float(a.mean())) < 0.02 and abs(float(a.std()) - 1.0) < 0.02
    assert abs(float((a.abs() < 1).float().mean()) - 0.6827) < 0.01  # P(|z| < 1) of N(0, 1)


def test_portable_adam_matches_torch_adam():
    start = _random(64, 3, seed=3)
    grads = [_random(64, 3, seed=10 + i) - 0.5 for i in range(6)]
    ours = start.clone().requires_grad_()
    theirs = start.clone().requires_grad_()
    mine = PortableAdam([{"params": [ours], "lr": 0.01}], eps=1e-15)
    reference = torch.optim.Adam([{"params": [theirs], "lr": 0.01}], eps=1e-15, foreach=False)
    for grad in grads:
        ours.grad, theirs.grad = grad.clone(), grad.clone()
        mine.step()
        reference.step()
    assert torch.allclose(ours, theirs, rtol=0, atol=2e-7)
    for key in ("exp_avg", "exp_avg_sq"):
        assert torch.allclose(mine.state[ours][key], reference.state[theirs][key], rtol=1e-6, atol=1e-7)
    assert float(mine.state[ours]["step"]) == 6.0


@pytest.mark.parametrize("border", ["same", "valid", "reflect"])
def test_exact_blur_equals_the_convolution(border):
    maps = _random(2, 5, 23, 37, dtype=torch.float64)
    assert torch.allclose(blur_exact(maps, 11, 1.5, border), blur_torch(maps, 11, 1.5, border), atol=1e-15)
    pred, target = _random(1, 3, 24, 40, seed=4), _random(1, 3, 24, 40, seed=5)
    exact = ssim(pred, target, border=border, backend="exact")
    assert torch.allclose(exact, ssim(pred, target, border=border, backend="torch"), atol=2e-6)


FIT_SCRIPT = """
import hashlib, sys
from setdiff_bench.gaussians.fit import FitConfig, fit_gaussians
from setdiff_bench.gaussians.fit import load_fit_scene, load_fit_views, select_fit_frames
from setdiff_bench.gaussians.ply import write_ply
from setdiff_bench.runtime.threads import torch_threads
scene = load_fit_scene(sys.argv[1])
views = load_fit_views(scene, select_fit_frames(scene, None))
config = FitConfig.schedule(24, densify_every=4, opacity_reset_every=12, tile_size=8, seed=5)
with torch_threads(int(sys.argv[3])):
    result = fit_gaussians(views, config, points=scene.points3d, colors=scene.points_rgb, progress=False)
write_ply(sys.argv[2], result.model)
"""


def _cpu_has_avx512() -> bool:
    try:
        return "avx512f" in Path("/proc/cpuinfo").read_text()
    except OSError:
        return False


def test_fit_is_byte_identical_across_instruction_sets_and_threads(tiny_scene_dir, tmp_path):
    variants = {
        "default ISA, 1 thread": ({"ATEN_CPU_CAPABILITY": "default", "ONEDNN_MAX_CPU_ISA": "SSE41"}, 1),
        "avx2, 2 threads": ({"ATEN_CPU_CAPABILITY": "avx2"}, 2),
    }
    if _cpu_has_avx512():
        variants["avx512, 3 threads"] = ({"ATEN_CPU_CAPABILITY": "avx512"}, 3)
    digests = {}
    for index, (name, (settings, threads)) in enumerate(variants.items()):
        ply = tmp_path / f"fit{index}.ply"
        env = {**os.environ, **settings}
        command = [sys.executable, "-c", FIT_SCRIPT, str(tiny_scene_dir), str(ply), str(threads)]
        result = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
        assert result.returncode == 0, result.stderr[-2000:]
        digests[name] = hashlib.sha256(ply.read_bytes()).hexdigest()
    assert len(set(digests.values())) == 1, digests
