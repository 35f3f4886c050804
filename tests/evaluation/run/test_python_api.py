"""Issue 57, the Python API on the way to one's own row: short reprs (shapes, names, checkpoint), per-target
scores with target names, a clear error for an unknown split, and a progress bar for ``run_method``."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import setdiff_bench as sb
from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.run import RunSettings, run_method

#: A repr is for reading at a prompt: one line of about this many characters at most.
SHORT = 400


def test_packet_and_score_reprs_are_short_and_say_what_matters(store: Path) -> None:
    packets = sb.PacketStore(store)
    packet_id = packets.packet_ids("test")[0]
    packet = packets.load_packet(packet_id)
    text = repr(packet)
    assert len(text) < SHORT and "\n" not in text, text
    # the fixture store: 2 references + 3 targets of 32 x 48 pixels per packet
    assert text.startswith(f"Packet({packet_id!r}, synthetic/synthetic/") and "2 references" in text
    assert f"3 targets {list(packet.targets.names)!r}" in text and "32x48 px" in text
    assert "images (3, 3, 32, 48) float32" in repr(packet.targets)
    assert "cmaps (2, 3, 32, 48) float32" in repr(packet.references)

    score = sb.score_packet(sb.create_enhancer("identity"), packets, packet_id)
    text = repr(score)
    assert len(text) < SHORT and "enhanced (3, 3, 32, 48) float32" in text, text
    assert f"psnr {score.means()['psnr']:.4g}" in text and packet.targets.names[0] in text
    # per-target scores carry the targets' names, in stored order
    assert score.targets == packet.targets.names
    table = score.per_target()
    assert list(table.index) == list(packet.targets.names) and table.index.name == "target"
    np.testing.assert_array_equal(table["psnr"].to_numpy(), score.scores["psnr"])
    assert list(table.columns) == ["psnr", "ssim", "lpips"]


def test_enhancer_reprs_name_what_was_built(store: Path, tmp_path: Path) -> None:
    from setdiff_bench.enhancers.difix import DifixEnhancer
    from setdiff_bench.enhancers.setdiff import ModelEnhancer
    from setdiff_bench.models.setdiff.files import MANIFEST_FILE

    # a stand-in model (loading a real one takes seconds): the repr reads only the checkpoint and options
    config = SimpleNamespace(
        model=SimpleNamespace(guidance_scale=1.0, max_references=4, targets_per_set=4, latent_factor=8)
    )
    exported = tmp_path / "my_model"
    exported.mkdir()
    (exported / MANIFEST_FILE).write_text("{}")
    options = {"guidance_scale": None, "sets_per_call": None}
    setdiff = ModelEnhancer("setdiff", torch.nn.Linear(1, 1), config, exported, **options)
    assert repr(setdiff) == (
        f"ModelEnhancer('setdiff', checkpoint='my_model', path={str(exported)!r}, device='cpu', dtype='float32')"
    )
    step = tmp_path / "train_run" / "step_000100"  # a training checkpoint: named with its run
    difix = DifixEnhancer(
        ModelEnhancer("difix", torch.nn.Linear(1, 1), config, step, **options), "nearest_pose"
    )
    assert repr(difix).startswith("DifixEnhancer('difix', checkpoint='train_run/step_000100', path=")
    assert repr(difix).endswith(", references='nearest_pose')")
    assert repr(sb.create_enhancer("identity")) == "IdentityEnhancer('identity')"
    # only the options that differ from the defaults
    assert repr(sb.create_enhancer("reproject", tolerance=0.05)) == (
        "ReprojectEnhancer('reproject', device='cpu', tolerance=0.05)"
    )
    assert repr(sb.create_enhancer("precomputed", source=str(store))) == (
        f"PrecomputedEnhancer('precomputed', source={str(store.resolve())!r})"
    )


def test_an_unknown_split_is_an_error_naming_the_valid_ones(store: Path) -> None:
    packets = sb.PacketStore(store)
    with pytest.raises(UsageError) as caught:
        packets.packet_ids("tset")
    assert str(caught.value) == (
        "split='tset': unknown split; valid splits: train, test, all (this store holds: test)"
    )
    # a split name the store holds no packets of is no typo: empty, as callers that check for it expect
    assert packets.packet_ids("train") == []
    assert packets.packet_ids("all") == packets.packet_ids() == sorted(packets.packet_ids("test"))


def test_run_method_shows_a_progress_bar_unless_told_not_to(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run_method(store, tmp_path / "bar", RunSettings("identity"))
    err = capsys.readouterr().err
    assert "identity [0/1]" in err and "4/4" in err and "packet" in err, err
    run_method(store, tmp_path / "quiet", RunSettings("identity"), progress=False)
    assert capsys.readouterr().err == ""
