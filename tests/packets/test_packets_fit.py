"""``prepare --fit``: the 3DGS is fitted on the group's fit frames, saved in the store and reused."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.packets.store import PacketStore
from tests.packets.packet_fixtures import prepare_argv


def test_fit_mode_trains_once_and_reuses_the_fit(street, tmp_path):
    root, _ = street
    out = tmp_path / "store"
    first = prepare("synthetic", root, out, fit=True, fit_iterations=20, scenes=["street_02"], progress=False)
    ply = out / "fits" / "street_02" / "lane0.ply"
    assert first.fits_trained == 1 and first.written == 5 and ply.is_file()
    assert not (out / "fits" / "street_02" / "lane0.ckpt").exists()
    assert len(read_ply(ply)) > 0
    assert set(PacketStore(out).index["scene"]) == {"street_02"}
    again = prepare("synthetic", root, out, fit=True, fit_iterations=20, scenes=["street_02"], progress=False)
    assert (again.fits_trained, again.written, again.skipped) == (0, 0, 5)


@pytest.mark.slow
def test_synth_tiny_preset_end_to_end(tmp_path):
    """The synthetic generator's own tiny scene (minutes on a busy CPU; the street fixture covers the same code)."""
    data, out = tmp_path / "data", tmp_path / "packets"
    for command in (
        ["synth", "--preset", "tiny", "--out", str(data), "--no-progress"],
        prepare_argv(data, out, "--quiet"),
    ):
        done = subprocess.run(
            [sys.executable, "-m", "setdiff_bench", *command], capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr
    store = PacketStore(out)
    assert store.verify() == [] and len(store) > 0
    assert set(store.index["group"]) == {"lane+1", "lane+2", "side", "turn", "interp"}
    shutil.rmtree(data)
