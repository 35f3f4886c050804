"""Issue 41 through the shipped models: ``tiny_setdiff`` and ``tiny_difix`` enhance a packet of the fox
walk-through's size (480×270, not a multiple of 8) and return exactly that size."""

from __future__ import annotations

import time

import pytest
import torch

from setdiff_bench.enhancers.base import create_enhancer
from setdiff_bench.runtime.threads import torch_threads
from tests.models.setdiff_fixtures import make_packet


@pytest.mark.parametrize(("method", "checkpoint"), [("setdiff", "tiny_setdiff"), ("difix", "tiny_difix")])
def test_shipped_models_enhance_the_fox_size(method: str, checkpoint: str) -> None:
    with torch_threads(1):
        enhancer = create_enhancer(method, checkpoint=checkpoint, device="cpu")
        packet = make_packet(2, 2, size=(270, 480), seed=7)
        start = time.perf_counter()
        output = enhancer.enhance(packet)
        seconds = time.perf_counter() - start
    assert output.shape == (2, 3, 270, 480) and output.dtype == torch.float32
    assert torch.isfinite(output).all() and float(output.min()) >= 0.0 and float(output.max()) <= 1.0
    # the model changes the render (it is not skipped by the padding path)
    assert float((output - packet.targets.images).abs().mean()) > 1e-3
    print(f"{checkpoint}: 2 targets of 480x270 in {seconds:.1f} s")
