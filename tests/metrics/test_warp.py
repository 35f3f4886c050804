"""Warp error: ≈0 on a known translation, analytic growth with flicker, hand-derived occlusion cases."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from skimage import data

from setdiff_bench.metrics.optical_flow import endpoint_error, flow_gray, synthetic_scene_pair
from setdiff_bench.metrics.warp import (
    PAPER_SCALE,
    OcclusionThresholds,
    WarpReference,
    backward_warp,
    occlusion_mask,
    warp_error,
    warp_error_pairs,
    warp_reference,
)


def translating_sequence(
    frames: int = 4, step: tuple[int, int] = (3, 2), size: tuple[int, int] = (96, 128)
) -> torch.Tensor:
    """``(T, 3, H, W)`` crops of a photograph sliding by ``step = (dx, dy)`` pixels per frame, range [0.1, 0.9]."""
    photo = torch.from_numpy(data.astronaut()).permute(2, 0, 1).double() / 255
    crops = [
        photo[:, 50 + step[1] * t : 50 + step[1] * t + size[0], 60 + step[0] * t : 60 + step[0] * t + size[1]]
        for t in range(frames)
    ]
    return 0.1 + 0.8 * torch.stack(crops)


@pytest.fixture(scope="module")
def sequence() -> torch.Tensor:
    return translating_sequence()


@pytest.fixture(scope="module")
def reference(sequence: torch.Tensor) -> WarpReference:
    return warp_reference(sequence)


def test_known_translation_gives_almost_zero(sequence: torch.Tensor, reference: WarpReference) -> None:
    # the content moves by (-3, -2) px from frame t to t+1
    np.testing.assert_allclose(reference.flow[:, 0].median(), -3.0, atol=0.02)
    np.testing.assert_allclose(reference.flow[:, 1].median(), -2.0, atol=0.02)
    naive = (sequence[1:] - sequence[:-1]).square().mean().item()
    error = warp_error(sequence, reference, scale=1.0).item()
    assert naive > 3e-3
    assert error < 1e-5
    assert warp_error(sequence, reference).item() == pytest.approx(error * PAPER_SCALE, rel=1e-9)


def test_error_grows_with_flicker_as_derived(sequence: torch.Tensor, reference: WarpReference) -> None:
    signs = torch.tensor([(-1.0) ** t for t in range(sequence.shape[0])], dtype=sequence.dtype).view(
        -1, 1, 1, 1
    )
    errors = []
    for amplitude in (0.0, 0.01, 0.03, 0.08):
        flickering = sequence + amplitude * signs  # stays inside [0, 1]: no clipping
        errors.append(warp_error(flickering, reference, scale=1.0).item())
        # consecutive frames differ by ±2a everywhere, so the error is (2a)² on top of the ~0 baseline
        assert errors[-1] == pytest.approx((2 * amplitude) ** 2, abs=2e-5)
    assert errors == sorted(errors) and errors[0] < errors[1]


def test_evaluation_mask_restricts_pixels(sequence: torch.Tensor, reference: WarpReference) -> None:
    damaged = sequence.clone()
    damaged[1:, :, :, :40] = 0.0  # frames 1.. broken on the left
    mask = torch.ones(sequence.shape[0], 1, *sequence.shape[-2:], dtype=torch.bool)
    mask[:, :, :, :50] = False  # frame t-1 pixels that land in the broken band (x-3 < 40) are excluded
    assert warp_error(damaged, reference, scale=1.0) > 1e-2
    assert warp_error(damaged, reference, mask, scale=1.0) < 1e-5


def test_backward_warp_integer_flow_is_a_shift() -> None:
    image = torch.arange(2 * 3 * 8 * 9, dtype=torch.float64).view(2, 3, 8, 9)
    flow = torch.zeros(2, 2, 8, 9, dtype=torch.float64)
    flow[:, 0], flow[:, 1] = 2.0, -1.0  # sample at (x + 2, y - 1)
    warped = backward_warp(image, flow)
    torch.testing.assert_close(warped[:, :, 1:, :-2], image[:, :, :-1, 2:])
    torch.testing.assert_close(warped[:, :, 0, :-2], image[:, :, 0, 2:])  # y clamped to the border row


def test_occlusion_rules_hand_derived() -> None:
    height, width = 6, 10
    forward = torch.zeros(1, 2, height, width, dtype=torch.float64)
    forward[:, 0] = 2.0
    consistent = -forward.clone()
    keep_all = OcclusionThresholds(exclude_out_of_frame=False)
    assert not occlusion_mask(forward, consistent, keep_all).any()
    # out-of-frame rule: targets x + 2 > 9 for x = 8, 9
    occluded = occlusion_mask(forward, consistent)
    assert occluded[0, 0, :, 8:].all() and not occluded[0, 0, :, :8].any()
    # inconsistent backward flow: |2 + 0|² = 4 > 0.01·(0 + 4) + 0.5
    assert occlusion_mask(forward, torch.zeros_like(forward), keep_all).all()
    # just under the threshold: |fw + bw|² = 0.49 < 0.01·(4 + 1.69) + 0.5
    assert not occlusion_mask(
        forward, torch.full_like(forward, 0.0).index_fill(1, torch.tensor([0]), -1.3), keep_all
    ).any()
    # motion boundary: u jumps from 0 to 5 between columns 4 and 5 → (0 − 5)² = 25 > 0.01·0 + 0.002 at x = 4
    step = torch.zeros(1, 2, height, width, dtype=torch.float64)
    step[:, 0, :, 5:] = 5.0
    boundary = occlusion_mask(step, -step, keep_all)[0, 0]
    assert boundary[:, 4].all()
    assert not boundary[:, :4].any()


def test_disocclusion_behind_a_moving_object_is_masked() -> None:
    background = data.coffee()[100:244, 100:292].astype(np.float64) / 255
    patch = data.astronaut()[60:108, 180:244].astype(np.float64) / 255
    frames = []
    for t in range(3):
        frame = background.copy()
        frame[40:88, 50 + 8 * t : 114 + 8 * t] = patch  # a 48×64 object moves right 8 px per frame
        frames.append(torch.from_numpy(frame).permute(2, 0, 1))
    frames = torch.stack(frames)
    reference = warp_reference(frames)
    assert reference.flow[0, 0, 60, 60:110].median() == pytest.approx(8.0, abs=0.1)
    # background pixels of frame 0 just right of the object are covered in frame 1 → occluded
    assert (~reference.valid[0, 0, 44:84, 114:122]).float().mean() > 0.8
    assert reference.valid[0, 0, :, :40].float().mean() > 0.95  # static background far away stays valid
    assert warp_error(frames, reference, scale=1.0) < 2e-4
    unmasked = WarpReference(reference.flow, torch.ones_like(reference.valid))
    assert warp_error(frames, unmasked, scale=1.0) > 5 * warp_error(frames, reference, scale=1.0)


def test_reference_round_trips_through_a_file(reference: WarpReference, tmp_path) -> None:
    path = tmp_path / "ref.safetensors"
    reference.save(path)
    loaded = WarpReference.load(path)
    torch.testing.assert_close(loaded.flow, reference.flow.float())
    assert torch.equal(loaded.valid, reference.valid)
    assert (loaded.method, loaded.thresholds) == (reference.method, reference.thresholds)
    (tmp_path / "bad.safetensors").write_bytes(b"nope")
    from setdiff_bench.errors import ImageError

    with pytest.raises(ImageError, match="not a warp reference"):
        WarpReference.load(tmp_path / "bad.safetensors")


def test_shape_mismatch_raises(reference: WarpReference) -> None:
    from setdiff_bench.errors import ImageError

    with pytest.raises(ImageError, match="do not match"):
        warp_error_pairs(torch.zeros(3, 3, 96, 128), reference)


def test_default_flow_method_is_the_more_accurate_on_known_flow() -> None:
    texture = cv2.resize(data.astronaut(), (640, 640), interpolation=cv2.INTER_CUBIC)
    obj = cv2.resize(data.coffee(), (300, 200), interpolation=cv2.INTER_AREA)[50:98, 100:164]
    scene = synthetic_scene_pair(
        texture,
        (144, 256),
        rotation=0.02,
        zoom=1.03,
        shift=(3.1, 1.2),
        object_texture=obj,
        object_origin=(100, 40),
        object_motion=(6, -2),
    )
    gray = [cv2.cvtColor((f * 255).round().astype(np.uint8), cv2.COLOR_RGB2GRAY) for f in scene[:2]]
    deepflow = endpoint_error(flow_gray(*gray, "deepflow"), scene.flow, scene.valid)
    dis = endpoint_error(flow_gray(*gray, "dis"), scene.flow, scene.valid)
    assert deepflow < 0.2
    assert deepflow < dis
