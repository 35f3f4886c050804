"""Issue 45, defect 7 (and the ``--sizes 20+1`` papercut): an ablation that is refused creates nothing.

Each refusal is one line ``setdiff-bench ablate: error: <file>: <problem>`` with exit code 2, and the
``--out`` folder (where ``work/ablation_*/stages.json`` and ``configs/*.toml`` used to appear) does not
exist afterwards.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store


@pytest.fixture(scope="module")
def test_only_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One scene, two groups, packets of 2 references + 3 targets, all in the ``test`` split."""
    with torch_threads(1):
        return build_store(tmp_path_factory.mktemp("store"), StoreSpec())


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str], out: Path) -> str:
    """Run ``argv``; assert exit 2, one stderr line, and no ``out``; return the line."""
    assert main([*argv, "--out", str(out), "--device", "cpu", "--no-progress"]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("setdiff-bench ablate: error: "), captured.err
    assert not out.exists(), sorted(str(p) for p in out.rglob("*"))
    return lines[0]


def test_setsize_missing_checkpoint(
    test_only_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    nope = tmp_path / "ckpt" / "nope"
    argv = [
        "ablate",
        "setsize",
        "--packets",
        str(test_only_store),
        "--checkpoint",
        str(nope),
        "--sizes",
        "1+1",
    ]
    line = _refused(argv, capsys, tmp_path / "abl_y")
    assert str(nope) in line


def test_setsize_more_references_than_the_packets_hold(
    test_only_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["ablate", "setsize", "--packets", str(test_only_store), "--checkpoint", "tiny_setdiff"]
    line = _refused([*argv, "--sizes", "1+1,20+1"], capsys, tmp_path / "abl")
    assert line == (
        "setdiff-bench ablate: error: --sizes: set size 20+1 needs 20 references per packet; "
        "the store's test packets have as few as 2"
    )


def test_setsize_not_a_store(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["ablate", "setsize", "--packets", str(tmp_path / "nowhere"), "--checkpoint", "tiny_setdiff"]
    assert "index.parquet" in _refused(argv, capsys, tmp_path / "abl")


def test_geometry_on_a_test_only_store(
    test_only_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["ablate", "geometry", "--packets", str(test_only_store), "--steps", "1"]
    line = _refused(argv, capsys, tmp_path / "abl")
    assert line == (
        f"setdiff-bench ablate: error: {test_only_store}: the geometry ablation needs train packets; "
        "this store has none (its splits: test)"
    )


def test_geometry_unknown_variant(
    test_only_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    store = build_store(tmp_path / "both", StoreSpec(split="train"))
    build_store(store, StoreSpec(scenes=("scene_b",)))  # the same folder gains test packets
    argv = ["ablate", "geometry", "--packets", str(store), "--variants", "none,colour"]
    assert "'colour' is unknown" in _refused(argv, capsys, tmp_path / "abl")
