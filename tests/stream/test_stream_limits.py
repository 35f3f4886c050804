"""The stream session's guards (issue 44): one warning when the references are unlike the model's training
data, and a tick too large for the memory refused before the model runs."""

from __future__ import annotations

import warnings

import pytest

from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.errors import MemoryNeedError
from setdiff_bench.evaluation.stream import StreamSession
from setdiff_bench.models.setdiff.domain import OutOfDistributionWarning
from setdiff_bench.runtime.memory import MEMORY_LIMIT_ENV
from tests.stream.stream_fixtures import HEIGHT, WIDTH, recorded_references, rig_camera, views


@pytest.mark.parametrize("model", ["tiny_setdiff", "tiny_difix"])
def test_session_of_another_size_warns_naming_both(model: str) -> None:
    enhancer = load_enhancer(model.removeprefix("tiny_"), model, device="cpu")
    with pytest.warns(OutOfDistributionWarning) as caught:
        session = StreamSession(enhancer, recorded_references())
    expected = f"{model} was trained on synthetic at 256×144; this session is images of {WIDTH}×{HEIGHT}"
    assert [str(w.message).split(":")[0] for w in caught] == [expected]
    assert session.out_of_distribution is not None


def test_session_at_the_training_size_does_not_warn() -> None:
    enhancer = load_enhancer("setdiff", "tiny_setdiff", device="cpu")
    with warnings.catch_warnings():
        warnings.simplefilter("error", OutOfDistributionWarning)
        session = StreamSession(enhancer, recorded_references(size=(144, 256)))
    assert session.out_of_distribution is None


def test_tick_too_large_for_the_memory_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    enhancer = load_enhancer("setdiff", "tiny_setdiff", device="cpu")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDistributionWarning)
        session = StreamSession(enhancer, recorded_references())
    frames = views([rig_camera(1.0, 0.0, lateral=3.0), rig_camera(3.0, 0.0, lateral=3.0)], seed=5)
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "64K")
    with pytest.raises(MemoryNeedError, match=r"needs about .* on cpu, 64 KB available; send fewer cameras"):
        session.enhance(frames)
    assert session.ticks == 0
    monkeypatch.delenv(MEMORY_LIMIT_ENV)
    assert session.enhance(frames).shape == (2, 3, HEIGHT, WIDTH)
