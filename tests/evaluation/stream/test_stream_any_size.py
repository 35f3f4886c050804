"""Issue 41: a stream session takes frames of any size (no longer only multiples of 8).

The streamed tick equals the batch runner on the same views, as at a multiple of 8, so the padding
is the enhancer's and the session adds nothing of its own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.evaluation.stream import StreamInputError, StreamSession
from setdiff_bench.io.images import read_rgb
from setdiff_bench.io.run_layout import IMAGES_DIR
from tests.evaluation.stream import stream_fixtures
from tests.evaluation.stream.stream_fixtures import (
    hwc,
    recorded_references,
    run_batch,
    tick_frames,
    write_tick_store,
)

SIZE = (27, 45)  # neither side a multiple of 8


def test_odd_size_tick_equals_batch_runner(
    checkpoint: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    enhancer = load_enhancer("setdiff", str(checkpoint), device="cpu")
    references = recorded_references(size=SIZE)
    session = StreamSession(enhancer, references)
    frames = tick_frames(3, size=SIZE)
    streamed = session.enhance(frames)
    assert streamed.shape == (3, 3, *SIZE) and torch.isfinite(streamed).all()

    # the fixture's store writer sizes its alphas and masks by the module's frame size
    monkeypatch.setattr(stream_fixtures, "HEIGHT", SIZE[0])
    monkeypatch.setattr(stream_fixtures, "WIDTH", SIZE[1])
    write_tick_store(tmp_path / "store", references, frames, session.select(frames.cameras), 3)
    run_batch(tmp_path / "store", tmp_path / "run", checkpoint)
    for position, name in enumerate(frames.names):
        [written] = [
            p
            for p in (tmp_path / "run" / IMAGES_DIR).rglob(Path(name).stem + ".png")
            if p.parent.name == Path(name).parent.name
        ]
        batch = np.rint(read_rgb(written) * 255).astype(np.int16)
        assert batch.shape == (*SIZE, 3)
        ours = np.rint(hwc(streamed[position]).clip(0, 1) * 255).astype(np.int16)
        assert np.abs(batch - ours).max() == 0


def test_a_tick_of_another_size_is_still_refused(checkpoint: Path) -> None:
    session = StreamSession(
        load_enhancer("setdiff", str(checkpoint), device="cpu"), recorded_references(SIZE)
    )
    with pytest.raises(StreamInputError, match="the session expects 45x27"):
        session.enhance(tick_frames(0, size=(32, 48)))


@pytest.mark.parametrize(("method", "shipped"), [("setdiff", "tiny_setdiff"), ("difix", "tiny_difix")])
def test_batch_run_of_shipped_models_on_an_odd_size_store(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, method: str, shipped: str
) -> None:
    """``run --method setdiff|difix --checkpoint tiny_*`` (the walk-through's door) on 45x27 packets."""
    monkeypatch.setattr(stream_fixtures, "HEIGHT", SIZE[0])
    monkeypatch.setattr(stream_fixtures, "WIDTH", SIZE[1])
    references, frames = recorded_references(size=SIZE), tick_frames(2, size=SIZE)
    write_tick_store(tmp_path / "store", references, frames, [0, 1, 2], 2)
    run_batch(tmp_path / "store", tmp_path / "run", shipped, method=method)
    written = sorted((tmp_path / "run" / IMAGES_DIR).rglob("*.png"))
    assert len(written) == 3 and all(read_rgb(p).shape == (*SIZE, 3) for p in written)
