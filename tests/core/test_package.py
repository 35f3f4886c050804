"""Packaging: the top-level loaders/ and protocols/ folders install as setdiff_bench subpackages."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_editable_install_maps_loaders_and_protocols() -> None:
    import setdiff_bench.loaders
    import setdiff_bench.protocols

    assert Path(setdiff_bench.loaders.__file__).resolve().parent == ROOT / "loaders"
    assert Path(setdiff_bench.protocols.__file__).resolve().parent == ROOT / "protocols"


def test_regular_install_contains_loaders_and_protocols(tmp_path: Path) -> None:
    target = tmp_path / "site"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--quiet",
            "--no-deps",
            "--no-build-isolation",
            "--target",
            str(target),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
    )
    code = (
        "import setdiff_bench.loaders as l, setdiff_bench.protocols as p, setdiff_bench.cli.main as m; "
        "print(l.__file__); print(p.__file__)"
    )
    result = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"},
        cwd=tmp_path,
    )
    loaders_file, protocols_file = result.stdout.split()
    assert Path(loaders_file).is_relative_to(target / "setdiff_bench" / "loaders")
    assert Path(protocols_file).is_relative_to(target / "setdiff_bench" / "protocols")
