"""End to end on a real packet store: write packets, `setdiff-bench train`, enhance a test packet."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.base import create_enhancer
from setdiff_bench.models.setdiff.checkpoint import resolve_checkpoint
from setdiff_bench.models.setdiff.inputs import training_set
from setdiff_bench.packets.store import PacketStore
from tests.models.setdiff_fixtures import STORE_TRAIN_CONFIG as CONFIG
from tests.models.setdiff_fixtures import UNIT_LABELS, train_argv, write_store


def test_train_on_a_packet_store_and_enhance(tmp_path: Path) -> None:
    write_store(tmp_path / "packets")
    config = tmp_path / "tiny.toml"
    config.write_text(CONFIG)
    out = tmp_path / "run"
    assert main(train_argv(config, tmp_path / "packets", out, "--cpu", "--no-progress")) == 0
    assert resolve_checkpoint(out).name == "step-00000002"
    assert (out / "validation.jsonl").read_text().count("psnr") == 1
    store = PacketStore(tmp_path / "packets")
    enhanced = create_enhancer("setdiff", checkpoint=str(out), device="cpu").enhance(
        store.load_packet("test-0")
    )
    assert enhanced.shape == (3, 3, 32, 32) and float(enhanced.min()) >= 0.0 and float(enhanced.max()) <= 1.0
    data = json.loads((out / "manifest.json").read_text())["data"]
    assert (data["datasets"], data["resolutions"]) == ([UNIT_LABELS["dataset"]], [[32, 32]])


def test_training_sets_from_the_store_keep_the_packet_invariant(tmp_path: Path) -> None:
    """The store draws the set; the trainer keeps it whole, permutes it and re-normalises it."""
    import random

    write_store(tmp_path / "packets")
    dataset = PacketStore(tmp_path / "packets").training_dataset("train", min_views=3, max_views=4, seed=0)
    sample = dataset[0]
    reordered = 0
    for seed in range(6):
        drawn = training_set(
            sample, random.Random(seed), min_views=3, max_views=4, use_geometry=True, cmap_clip=0.0
        )
        n = drawn.batch.num_references
        assert drawn.batch.num_views == len(sample.packet.references) + len(sample.packet.targets)
        reordered += not torch.equal(drawn.batch.images[0, n], sample.packet.targets.images[0])
        geometry = drawn.batch.geometry[0]
        first_target = geometry[n]
        assert float(first_target[3:6].abs().max()) < 1e-6  # Plücker moment o × d = 0: camera at the origin
        height, width = first_target.shape[-2:]
        centre = first_target[6:9, height // 2 - 1 : height // 2 + 1, width // 2 - 1 : width // 2 + 1].mean(
            dim=(1, 2)
        )
        assert float(centre[2]) > 0.99  # its centre rays look down its own +z
        # unit extent around the first target at the origin: every centre o has |o| <= 1, so |o × d| <= 1
        assert float(geometry[:, 3:6].norm(dim=1).max()) <= 1.0 + 1e-5
    assert reordered > 0  # the permutation did move another target first, and the frame followed it
