"""Where the demo reads and writes: :class:`DemoPaths` (``<out>`` for tables, plots and the report,
``<work>`` for scenes, packets, checkpoints and runs) and the names of its report and summary files."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

#: The demo's summary in ``<out>``; written last, so a folder with it holds one complete run.
SUMMARY_FILE = "demo.json"
#: The demo's report in ``<out>``: what ran, how long, the tables and the files.
REPORT_FILE = "README.md"
#: Which benchmark a demo folder holds, in ``<work>`` (one line: its name), written before the first stage.
BENCHMARK_FILE = "benchmark"


@dataclass(frozen=True)
class DemoPaths:
    """Where the demo reads and writes (all under ``out``)."""

    out: Path
    work: Path

    @property
    def scenes(self) -> Path:
        return self.work / "scenes"

    @property
    def packets(self) -> Path:
        return self.work / "packets"

    def checkpoints(self, method: str) -> Path:
        return self.work / "checkpoints" / method

    @property
    def runs(self) -> Path:
        return self.work / "runs"

    def refits(self, method: str) -> Path:
        """``demo --refit``: the ``refit --out`` folder of one enhancer's refits (every test scene's)."""
        return self.work / "refit" / method

    def refit_packets(self, name: str) -> Path:
        """``demo --refit``: the packets of the refit scenes a row (``X-3D``, ``X-3D-000100``) is scored on."""
        return self.work / "refit_packets" / name
