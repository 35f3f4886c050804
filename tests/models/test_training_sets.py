"""Training sets shaped like the test: all references + 1–4 targets, a share of draws from the sparsest
packets, masked-copy holes only where a reference sees the surface (hand-built geometry)."""

from __future__ import annotations

import random
from dataclasses import replace

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError
from setdiff_bench.models.setdiff.config import TrainConfig, config_from_dict
from setdiff_bench.models.setdiff.config_io import load_config
from setdiff_bench.models.setdiff.inputs import HOLE_VALUE, cut_holes, reference_visibility, training_set
from setdiff_bench.models.setdiff.sample_stream import SampleStream, dataset_reference_counts
from setdiff_bench.types import ViewSet
from tests.models.setdiff_fixtures import make_packet, make_sample


def test_test_shaped_sets_hold_every_reference_and_one_to_four_targets() -> None:
    sample = make_sample(3, 10, size=(16, 16))
    reference_images = sample.packet.references.images
    seen_counts = set()
    for draw in range(40):
        drawn = training_set(
            sample,
            random.Random(draw),
            min_views=4,
            max_views=8,
            use_geometry=True,
            cmap_clip=10.0,
            set_shape="test",
            test_targets=(1, 4),
        )
        batch = drawn.batch
        assert batch.num_references == 3
        seen_counts.add(batch.num_targets)
        # the three references, in some order (exact images: no renormalisation touches them)
        got = sorted(float(batch.images[0, i].sum()) for i in range(3))
        assert got == pytest.approx(sorted(float(image.sum()) for image in reference_images))
    assert seen_counts == {1, 2, 3, 4}


def test_defaults_keep_the_old_recipe() -> None:
    train = TrainConfig()
    assert (train.set_shape, train.sparsest_share, train.masked_copy_visible, train.distill_from) == (
        "proportional",
        0.0,
        False,
        None,
    )
    assert load_config("tiny_setdiff").train.set_shape == "proportional"
    with pytest.raises(UsageError, match="test_targets"):
        config_from_dict({"train": {"test_targets": [3, 1]}})
    with pytest.raises(UsageError, match="sparsest_share"):
        config_from_dict({"train": {"sparsest_share": 1.0}})
    with pytest.raises(UsageError, match="set_shape"):
        config_from_dict({"train": {"set_shape": "paper"}})


def test_sparsest_share_of_draws() -> None:
    """2 of 10 packets have 3 references; with share 0.6 about 60 % of 2000 draws are theirs (binomial
    standard error 1.1 %), both are drawn, and a resumed stream continues the same sequence."""
    counts = [3, 6, 9, 6, 3, 9, 9, 6, 6, 9]
    dataset = list(range(10))  # the stream only indexes it
    stream = SampleStream(dataset, seed=4, sparsest_share=0.6, reference_counts=counts)  # type: ignore[arg-type]
    drawn = [next(stream) for _ in range(2000)]
    share = sum(counts[i] == 3 for i in drawn) / len(drawn)
    assert 0.56 < share < 0.64
    assert {i for i in drawn if counts[i] == 3} == {0, 4}
    resumed = SampleStream(dataset, seed=4, sparsest_share=0.6, reference_counts=counts, start=1234)  # type: ignore[arg-type]
    assert [next(resumed) for _ in range(50)] == drawn[1234:1284]
    plain = SampleStream(dataset, seed=4)  # type: ignore[arg-type]
    assert sorted(next(plain) for _ in range(10)) == list(range(10))  # a permutation per epoch, as before


def test_reference_counts_of_a_sample_list() -> None:
    samples = [make_sample(n, 1, size=(8, 8), seed=n) for n in (3, 1, 2)]
    assert dataset_reference_counts(samples) == [3, 1, 2]


def plane_views(count: int, depth_left: float) -> ViewSet:
    """``count`` 8×8 views from the origin looking down +z at the plane z = 2, except that the left half of
    the image (columns 0–3) sees a surface at depth ``depth_left``; alpha 1 everywhere, C-map = the point."""
    K = np.array([[8.0, 0, 4.0], [0, 8.0, 4.0], [0, 0, 1]])
    camera = Camera(K=K, w2c=np.eye(4), width=8, height=8)
    v, u = np.meshgrid(np.arange(8) + 0.5, np.arange(8) + 0.5, indexing="ij")
    depth = np.where(u < 4, depth_left, 2.0)
    points = camera.unproject(np.stack([u.ravel(), v.ravel()], 1), depth.ravel())  # (64, 3)
    cmap = torch.from_numpy(points.T.reshape(3, 8, 8)).float()
    return ViewSet(
        names=tuple(f"v{i}" for i in range(count)),
        images=torch.full((count, 3, 8, 8), 0.2),
        cmaps=cmap.expand(count, -1, -1, -1).clone(),
        alphas=torch.ones(count, 1, 8, 8),
        cameras=(camera,) * count,
    )


def test_reference_visibility_by_hand() -> None:
    """Target and reference share a pose; the reference's left half sees an occluder at z = 1 in front of
    the plane z = 2, so it sees only the target's right half (|1 − 2| > 3 % of 2); with no occluder, all."""
    packet = make_packet(1, 1, size=(8, 8))
    occluded = replace(packet, references=plane_views(1, 1.0), targets=plane_views(1, 2.0))
    seen = reference_visibility(occluded)[0, 0]
    expected = torch.zeros(8, 8, dtype=torch.bool)
    expected[:, 4:] = True
    assert torch.equal(seen, expected)
    clear = replace(packet, references=plane_views(1, 2.0), targets=plane_views(1, 2.0))
    assert bool(reference_visibility(clear).all())


def test_visible_holes_blank_only_seen_pixels() -> None:
    images = torch.rand(2, 3, 16, 16)
    alphas = torch.ones(2, 1, 16, 16)
    visible = torch.zeros(2, 1, 16, 16, dtype=torch.bool)
    visible[0, 0, 4:12, 6:10] = True  # view 1: nothing seen
    holes = cut_holes(images, alphas, random.Random(3), visible)
    blanked = (holes != images).any(dim=1, keepdim=True)
    assert blanked[0].any() and not (blanked & ~visible).any()
    assert torch.equal(holes[1], images[1])
    assert bool((holes[0][:, blanked[0, 0]] == HOLE_VALUE).all())


def test_masked_copy_visible_in_a_training_set() -> None:
    sample = make_sample(2, 2, size=(16, 16))
    drawn = training_set(
        sample,
        random.Random(0),
        min_views=4,
        max_views=8,
        use_geometry=True,
        cmap_clip=10.0,
        masked_copy_probability=0.999,
        masked_copy_visible=True,
    )
    assert drawn.batch.images.shape[1] == 4 and torch.isfinite(drawn.batch.images).all()
