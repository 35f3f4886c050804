"""Outputs honour the umask: atomic writes through temporary files and staged folders get the modes an
ordinary ``open`` / ``mkdir`` would give (``tempfile`` alone gives 0600 / 0700)."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.io.atomic import atomic_path, current_umask, staging_dir, write_text_atomic
from setdiff_bench.io.images import write_exr, write_png
from setdiff_bench.io.run_layout import METRICS_FILE


@pytest.fixture(params=[0o022, 0o027, 0o002])
def umask(request: pytest.FixtureRequest) -> Iterator[int]:
    previous = os.umask(request.param)
    try:
        yield request.param
    finally:
        os.umask(previous)


def mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_current_umask_reads_the_process_umask(umask: int) -> None:
    assert current_umask() == umask
    assert current_umask() == umask  # reading it does not change it


def test_atomic_text_file_gets_the_umask_mode(tmp_path: Path, umask: int) -> None:
    target = tmp_path / "sub" / "table.md"
    write_text_atomic(target, "x\n")
    expected = {0o022: 0o644, 0o027: 0o640, 0o002: 0o664}[umask]
    assert mode(target) == expected
    assert mode(target.parent) == {0o022: 0o755, 0o027: 0o750, 0o002: 0o775}[umask]


def test_atomic_path_written_by_a_library_gets_the_umask_mode(tmp_path: Path, umask: int) -> None:
    expected = 0o666 & ~umask
    write_png(tmp_path / "a.png", np.zeros((4, 5, 3), np.uint8))
    write_exr(tmp_path / "a.exr", np.zeros((4, 5, 3), np.float32))
    with atomic_path(tmp_path / "b.bin") as tmp:
        tmp.write_bytes(b"123")
    for name in ("a.png", "a.exr", "b.bin"):
        assert mode(tmp_path / name) == expected, name


def test_staging_dir_gets_the_umask_folder_mode(tmp_path: Path, umask: int) -> None:
    folder = staging_dir(tmp_path, prefix=".x.", suffix=".tmp")
    assert folder.parent == tmp_path and folder.name.startswith(".x.") and folder.name.endswith(".tmp")
    assert mode(folder) == 0o777 & ~umask


def test_stale_temporaries_are_those_of_dead_writers_or_old_foreign_ones(tmp_path: Path) -> None:
    import os
    import subprocess
    import sys

    from setdiff_bench.io.atomic import STALE_TEMPORARY_SECONDS, atomic_path, is_stale_temporary, writer_tag

    with atomic_path(tmp_path / METRICS_FILE) as tmp:  # this process's write in progress
        assert writer_tag() in tmp.name and not is_stale_temporary(tmp)
    gone = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True
    )
    host = writer_tag().rsplit("-", 1)[0]
    dead = tmp_path / f".metrics.{host}-{gone.stdout.strip()}.abc123.tmp.parquet"  # a killed writer here
    dead.write_bytes(b"")
    assert is_stale_temporary(dead)
    foreign = tmp_path / ".metrics.wsomewhere-else-7.abc123.tmp.parquet"  # another machine's writer
    foreign.write_bytes(b"")
    assert not is_stale_temporary(foreign)
    old = foreign.stat().st_mtime - STALE_TEMPORARY_SECONDS - 10
    os.utime(foreign, (old, old))
    assert is_stale_temporary(foreign)
