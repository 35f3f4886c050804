"""The stream session's guards (issue 44): one warning when the references are unlike the model's training
data, and a tick too large for the memory refused before the model runs."""

from __future__ import annotations

import warnings

import pytest

from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.errors import MemoryNeedError, OutOfDistributionWarning
from setdiff_bench.evaluation.stream import StreamSession
from setdiff_bench.runtime.memory import MEMORY_LIMIT_ENV
from tests.evaluation.stream.stream_fixtures import HEIGHT, WIDTH, recorded_references, rig_camera, views


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


def test_served_tick_too_large_is_resource_exhausted_and_the_domain_warned() -> None:
    """A real ``serve`` process under a 64 KiB memory cap: the session starts, a tick is refused with
    ``RESOURCE_EXHAUSTED`` and the one-line reason, and the server's log names the domain mismatch once."""
    import grpc

    from setdiff_bench.serve.client import EnhancerClient
    from tests.evaluation.stream.stream_fixtures import serve_argv, tick_frames
    from tests.serve.serve_fixtures import environment, served

    with served(serve_argv("tiny_setdiff"), env=environment(SETDIFF_MEMORY_LIMIT="64K")) as (process, port):
        with EnhancerClient(f"127.0.0.1:{port}", timeout=60) as client:
            client.wait_ready()
            session = client.start_session(recorded_references())
            with pytest.raises(grpc.RpcError) as refused:
                client.enhance(session, tick_frames(0))
            assert refused.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
            assert "needs about" in refused.value.details() and "64 KB available" in refused.value.details()
            client.close_session(session)
        process.terminate()
        _, log = process.communicate(timeout=30)
    warned = [line for line in log.splitlines() if "was trained on synthetic at 256×144" in line]
    assert len(warned) == 1 and "this session is images of 48×32" in warned[0], log
