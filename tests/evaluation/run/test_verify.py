"""A corrupt packet file stops ``run`` before any work (the up-front SHA-256 check), not when the run reaches it."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.enhancers.identity import IdentityEnhancer
from setdiff_bench.errors import PacketError
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.packets.index import INDEX_FILE


class CountingIdentity(IdentityEnhancer):
    def __init__(self) -> None:
        super().__init__()
        self.calls = 0

    def enhance(self, packet):  # type: ignore[no-untyped-def]
        self.calls += 1
        return super().enhance(packet)


def corrupt_last_packet(store: Path, tmp_path: Path) -> tuple[Path, Path]:
    copy = tmp_path / "store"
    shutil.copytree(store, copy)
    index = pd.read_parquet(copy / INDEX_FILE)
    last = sorted(index["packet_id"].unique())[-1]
    victim = copy / index[(index["packet_id"] == last) & (index["role"] == "target")]["gt"].iloc[0]
    victim.write_bytes(victim.read_bytes()[:-7])  # a truncated ground-truth PNG
    return copy, victim


def run_on_corrupt_store(store: Path, tmp_path: Path, *, verify: bool) -> tuple[PacketError, int, Path]:
    """``run`` identity on a copy of ``store`` with one truncated file: the error, how many packets the
    enhancer saw before it, and the truncated file."""
    copy, victim = corrupt_last_packet(store, tmp_path)
    enhancer = CountingIdentity()
    with pytest.raises(PacketError, match="SHA-256 mismatch") as error:
        run_method(
            copy,
            tmp_path / "out",
            RunSettings(method="identity", device="cpu"),
            progress=False,
            enhancer=enhancer,
            verify=verify,
        )
    return error.value, enhancer.calls, victim


def test_corrupt_file_is_found_before_any_work(store: Path, tmp_path: Path) -> None:
    error, calls, victim = run_on_corrupt_store(store, tmp_path, verify=True)
    assert calls == 0 and error.path == str(victim)
    assert "SHA-256 mismatch" in error.problem and "before any work" in error.problem
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").rglob("*.parquet"))


def test_without_the_check_the_run_finds_it_late(store: Path, tmp_path: Path) -> None:
    _, calls, _ = run_on_corrupt_store(store, tmp_path, verify=False)
    assert calls > 0  # packets before the corrupt one were enhanced first
