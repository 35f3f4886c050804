"""A store mixing packets with ground truth and novel-trajectory packets without (issue 41): training's
validation, the autoencoder's frames and profile scoring leave the targets without ground truth out instead
of stopping at the first one."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from setdiff_bench.cli.main import main
from setdiff_bench.evaluation.profile_scoring import score_run
from setdiff_bench.models.setdiff.autoencoder_train import ground_truth_frames
from setdiff_bench.models.setdiff.config_io import load_config
from setdiff_bench.packets.index import NoGroundTruthError
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.protocols.profiles import EvaluationProfile
from setdiff_bench.runtime.threads import torch_threads


@pytest.fixture(scope="module")
def mixed(prepared, street, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The session store plus ``shift:-3`` packets of street_02 (split test, no ground truth)."""
    root, _ = street
    out = tmp_path_factory.mktemp("mixed") / "store"
    shutil.copytree(prepared[0], out)
    with torch_threads(1):
        prepare(
            "synthetic",
            root,
            out,
            fits=root,
            progress=False,
            trajectories=("shift:-3",),
            scenes=["street_02"],
        )
    return out


def _without(index: pd.DataFrame) -> set[str]:
    """Packet ids whose targets have null ``gt`` (read from the index, not through the store)."""
    targets = index[index["role"] == "target"]
    return set(targets[targets["gt"].isna()]["packet_id"])


def test_the_fixture_mixes_both_kinds(mixed: Path) -> None:
    index = pd.read_parquet(mixed / "index.parquet")
    test_ids = set(index[index["split"] == "test"]["packet_id"])
    assert _without(index) and _without(index) < test_ids and test_ids - _without(index)
    with pytest.raises(NoGroundTruthError):
        PacketStore(mixed).load_ground_truth(sorted(_without(index))[0])


def test_autoencoder_frames_skip_targets_without_ground_truth(mixed: Path) -> None:
    index = pd.read_parquet(mixed / "index.parquet")
    test = index[index["split"] == "test"]
    # by hand: the SHA-256 of every reference image file and of every ground-truth file that exists
    expected = {
        hashlib.sha256((mixed / p).read_bytes()).hexdigest() for p in test[test["role"] == "ref"]["image"]
    }
    expected |= {hashlib.sha256((mixed / p).read_bytes()).hexdigest() for p in test["gt"].dropna()}
    frames = ground_truth_frames(PacketStore(mixed), "test")
    assert set(frames.hashes) == expected and len(frames.hashes) == len(expected)
    # the trajectory packets' references are recorded frames and count; their render files do not
    renders = {hashlib.sha256((mixed / p).read_bytes()).hexdigest() for p in test[test["gt"].isna()]["image"]}
    renders -= expected
    assert renders and not renders & set(frames.hashes)


def test_training_validation_skips_packets_without_ground_truth(
    mixed: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import setdiff_bench.models.setdiff.train as train_module

    captured: dict[str, object] = {}

    class Captured(Exception):
        pass

    def fake_train(config, dataset, out_dir, *, validation=(), **_: object):
        captured["validation"] = list(validation)
        raise Captured

    monkeypatch.setattr(train_module, "train", fake_train)
    index = pd.read_parquet(mixed / "index.parquet")
    with_gt = sorted(set(index[index["split"] == "test"]["packet_id"]) - _without(index))
    with pytest.raises(Captured):
        main(["train", "--config", "tiny_setdiff", "--packets", str(mixed), "--out", str(tmp_path / "m")])
    count = load_config("tiny_setdiff").train.validation_packets
    assert len(with_gt) >= 1 and len(_without(index)) >= 1
    validation = captured["validation"]
    # the first scorable packets in id order, none of the trajectory packets
    assert [s.packet.packet_id for s in validation] == with_gt[:count]


def test_profile_scoring_leaves_targets_without_ground_truth_out(mixed: Path, tmp_path: Path) -> None:
    run = tmp_path / "identity"
    with torch_threads(1):
        assert (
            main(["run", "--method", "identity", "--packets", str(mixed), "--out", str(run), "--no-progress"])
            == 0
        )
    metrics = pd.read_parquet(run / "metrics.parquet")
    without = metrics[metrics["psnr"].isna()]
    assert len(without) == 4 and set(without["group"]) == {"shift-3m"}
    profile = EvaluationProfile("psnr_only", "working size, PSNR", "", ("psnr",))
    out = score_run(run, profile, packets=mixed, progress=False)
    scored = pd.read_parquet(out / "metrics.parquet")
    kept = metrics.dropna(subset=["psnr"]).drop_duplicates(["method", "group", "scene", "frame"])
    assert len(scored) == len(kept) and "shift-3m" not in set(scored["group"])
    # PSNR of every scored target by hand from the PNG files (identity: the render against the ground truth)
    index = pd.read_parquet(mixed / "index.parquet").set_index(["packet_id", "role", "view"])
    for row in scored.merge(kept[["group", "scene", "frame", "packet_id", "view", "image"]]).to_dict(
        "records"
    ):
        entry = index.loc[(row["packet_id"], "target", row["view"])]
        prediction = np.asarray(Image.open(run / row["image"]).convert("RGB"), dtype=np.float64) / 255
        truth = np.asarray(Image.open(mixed / entry["gt"]).convert("RGB"), dtype=np.float64) / 255
        mask = np.asarray(Image.open(mixed / entry["mask"]).convert("L")) > 127
        mse = ((prediction - truth) ** 2)[mask].mean()
        assert row["psnr"] == pytest.approx(10 * np.log10(1 / mse), abs=1e-3)
    info = (out / "profile.json").read_text()
    assert "4 target(s) without ground truth (novel-trajectory views) left out" in info
    assert np.isfinite(scored["psnr"]).all()
    # a run of trajectory targets only: one clear error
    only = tmp_path / "only"
    shutil.copytree(run, only)
    table = pd.read_parquet(only / "metrics.parquet")
    table[table["psnr"].isna()].to_parquet(only / "metrics.parquet", index=False)
    with pytest.raises(Exception, match="every target of this run is a novel-trajectory view"):
        score_run(only, profile, packets=mixed, progress=False)
