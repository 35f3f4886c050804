"""The in-process stream API against the batch runner (``run --method setdiff``) on the same views."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.evaluation.stream import StreamInputError, StreamSession, Views
from setdiff_bench.io.images import read_rgb, uint8_to_float
from setdiff_bench.io.run_layout import IMAGES_DIR
from tests.evaluation.stream.stream_fixtures import (
    HEIGHT,
    WIDTH,
    hwc,
    recorded_references,
    rig_camera,
    run_batch,
    tick_frames,
    write_tick_store,
)


@pytest.mark.parametrize("tick", [0, 7])
def test_equals_batch_runner_to_the_last_8bit_level(checkpoint: Path, tmp_path: Path, tick: int) -> None:
    enhancer = load_enhancer("setdiff", str(checkpoint), device="cpu")
    references = recorded_references()
    session = StreamSession(enhancer, references)
    frames = tick_frames(tick)
    chosen = session.select(frames.cameras)
    assert len(chosen) == 3
    streamed = session.enhance(frames)

    write_tick_store(tmp_path / "store", references, frames, chosen, tick)
    run_batch(tmp_path / "store", tmp_path / "run", checkpoint)
    for position, name in enumerate(frames.names):
        written = sorted((tmp_path / "run" / IMAGES_DIR).rglob(Path(name).stem + ".png"))
        written = [p for p in written if p.parent.name == Path(name).parent.name]
        assert len(written) == 1, written
        batch = np.rint(read_rgb(written[0]) * 255).astype(np.int16)
        ours = np.rint(hwc(streamed[position]).clip(0, 1) * 255).astype(np.int16)
        assert np.abs(batch - ours).max() == 0


def test_reference_selection_follows_eq2(checkpoint: Path) -> None:
    """Frames near recorded frames 3–5 choose those (Eq. 2: closest centres, same heading)."""
    session = StreamSession(load_enhancer("setdiff", str(checkpoint), device="cpu"), recorded_references())
    near_end = [rig_camera(8.0 + 0.1 * i, 0.0) for i in range(3)]
    assert session.select(near_end) == [3, 4, 5]
    near_start = [rig_camera(0.1 * i, 0.0) for i in range(3)]
    assert session.select(near_start) == [0, 1, 2]


def test_bad_ticks_are_refused(checkpoint: Path) -> None:
    session = StreamSession(
        load_enhancer("setdiff", str(checkpoint), device="cpu"), recorded_references(), max_cameras=3
    )
    frames = tick_frames(0)
    with pytest.raises(StreamInputError, match="expects 48x32"):
        session.enhance(Views(torch.zeros(3, 3, 16, 48, dtype=torch.uint8), frames.cameras, frames.cmaps))
    nan = uint8_to_float(frames.images)
    nan[0, 0, 0, 0] = float("nan")
    with pytest.raises(StreamInputError, match="NaN"):
        session.enhance(Views(nan, frames.cameras, frames.cmaps))
    with pytest.raises(StreamInputError, match="at most 3"):
        session.enhance(
            Views(torch.cat([frames.images, frames.images[:1]]), [*frames.cameras, frames.cameras[0]])
        )
    with pytest.raises(StreamInputError, match="no PLY"):
        session.enhance(Views(frames.images, frames.cameras))
    assert session.enhance(frames).shape == (3, 3, HEIGHT, WIDTH)  # still serving


def test_bytes_convert_as_a_png_is_read(tmp_path: Path) -> None:
    from setdiff_bench.io.images import write_png

    values = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, axis=2)
    write_png(tmp_path / "ramp.png", values)
    assert np.array_equal(uint8_to_float(values).numpy(), read_rgb(tmp_path / "ramp.png"))


def test_reference_latent_cache_reuses_latents_within_one_8bit_level(checkpoint: Path) -> None:
    enhancer = load_enhancer("setdiff", str(checkpoint), device="cpu")
    cached = StreamSession(enhancer, recorded_references(), cache_reference_latents=True)
    uncached = StreamSession(enhancer, recorded_references())
    for tick in range(4):
        a, b = cached.enhance(tick_frames(tick)), uncached.enhance(tick_frames(tick))
        assert (torch.round(a * 255) - torch.round(b * 255)).abs().max() <= 1, tick
        assert (a - b).abs().max() < 1e-4
    # tick 0 encodes its 3 references; ticks 1–3 reuse them (each tick uses 3 of the 6 recordings)
    assert cached.latent_cache.misses == 3 * 4 + len(cached.latent_cache.latents)
    assert cached.latent_cache.hits == 3 * 4 - len(cached.latent_cache.latents)
    assert "encode" not in vars(enhancer.model)  # the model is left as it was
