"""Issue 45, defect 5: the numbers of docs/evaluation_profiles.md come from the commands printed beside them.

The test reads the example section of the document (its shell block and its table), runs the block's
commands as written in a fresh folder, and compares every documented value with the tables the commands
wrote, at the precision the document prints: the per-block PSNR / SSIM / LPIPS of both profiles, the
largest PSNR gap between them ("moves PSNR by up to ... dB"), the rescoring agreement ("to within
2·10⁻⁶ dB") and the count of positionally mispaired targets.  The block takes about a minute on 2 cores
(three tiny 80×48 scenes), so it runs with the default suite, twice: with the machine's own kernels and
with the scalar ones (``ATEN_CPU_CAPABILITY=default``), which gave other numbers before scene fits were
made CPU-independent (setdiff_bench/gaussians/portable.py).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "evaluation_profiles.md"
SECTION = "## Example: how far apart the profiles put the same run"
#: Table row label → the protocol group it shows.
GROUPS = {
    "Lane +1": "lane+1",
    "Lane +2": "lane+2",
    "Side cameras": "side",
    "Turn": "turn",
    "Held-out": "interp",
}


def documented() -> tuple[list[str], dict[str, tuple[list[str], list[str]]], str]:
    """The section's commands, ``{group: (paper values, euvs_official values)}`` as printed, and its prose."""
    text = DOC.read_text(encoding="utf-8").split(SECTION, 1)[1].split("\n## ", 1)[0]
    block = text.split("```", 2)[1]
    commands = [line.strip() for line in block.strip("\n").splitlines() if line.strip()]
    rows = {}
    for line in text.splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if len(cells) == 3 and cells[0] in GROUPS:
            rows[GROUPS[cells[0]]] = (cells[1].split(" / "), cells[2].split(" / "))
    return commands, rows, text


def _shown(value: float, template: str) -> str:
    """``value`` at the number of decimals of ``template`` (``20.29`` → 2)."""
    decimals = len(template.split(".", 1)[1]) if "." in template else 0
    return f"{value:.{decimals}f}"


#: The machine's own kernels, and the scalar ones an older CPU runs (ATen without vector instructions,
#: oneDNN at SSE4.1): the documented numbers must come out of both (scene fits are CPU-independent).
INSTRUCTION_SETS = {
    "native": {},
    "default-isa": {"ATEN_CPU_CAPABILITY": "default", "ONEDNN_MAX_CPU_ISA": "SSE41"},
}


@pytest.fixture(scope="module", params=sorted(INSTRUCTION_SETS))
def outputs(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The folder the documented commands ran in and the output of the EUVS ``evaluate``, once per
    instruction set of :data:`INSTRUCTION_SETS`."""
    folder = tmp_path_factory.mktemp("evaluation_profiles")
    commands, _, _ = documented()
    env = {
        **os.environ,
        **INSTRUCTION_SETS[request.param],
        "SETDIFF_THREADS": "1",
        "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
    }
    printed = {}
    for command in commands:
        assert command.startswith("setdiff-bench "), command
        result = subprocess.run(["bash", "-c", command], cwd=folder, env=env, capture_output=True, text=True)
        assert result.returncode == 0, (command, result.stderr[-2000:])
        printed[command] = result.stdout
    euvs = next(out for command, out in printed.items() if "--euvs-compat-report" in command)
    return folder, euvs


def test_documented_table_reproduces(outputs: tuple[Path, str]) -> None:
    folder, _ = outputs
    _, rows, _ = documented()
    assert set(rows) >= {"lane+1", "side"}  # the document's table was read
    paper = pd.read_parquet(folder / "runs/identity/profiles/paper/groups.parquet").set_index("group")
    euvs = pd.read_parquet(folder / "runs/identity/profiles/euvs_official/groups.parquet").set_index("group")
    for group, (paper_doc, euvs_doc) in rows.items():
        measured_paper = [paper.loc[group, m] for m in ("psnr", "ssim", "lpips")]
        measured_euvs = [euvs.loc[group, m] for m in ("psnr_euvs", "ssim_euvs", "lpips_euvs")]
        assert [_shown(v, t) for v, t in zip(measured_paper, paper_doc)] == paper_doc, group
        assert [_shown(v, t) for v, t in zip(measured_euvs, euvs_doc)] == euvs_doc, group


def test_documented_prose_reproduces(outputs: tuple[Path, str]) -> None:
    folder, euvs_printed = outputs
    _, _, text = documented()
    paper = pd.read_parquet(folder / "runs/identity/profiles/paper/groups.parquet").set_index("group")
    euvs = pd.read_parquet(folder / "runs/identity/profiles/euvs_official/groups.parquet").set_index("group")
    gap = max(abs(paper.loc[g, "psnr"] - euvs.loc[g, "psnr_euvs"]) for g in paper.index)
    assert f"moves PSNR by up to {gap:.1f} dB" in " ".join(text.split())
    own = pd.read_parquet(folder / "runs/identity/metrics.parquet")
    rescored = pd.read_parquet(folder / "runs/identity/profiles/paper/metrics.parquet")
    keys = ["packet_id", "view"]
    joined = own.merge(rescored, on=keys, suffixes=("_run", "_profile"))
    assert len(joined) == len(rescored) > 0
    assert (joined["psnr_run"] - joined["psnr_profile"]).abs().max() <= 2e-6  # "to within 2·10⁻⁶ dB"
    mispaired = sum(line.strip().startswith("mispaired:") for line in euvs_printed.splitlines())
    count = int(re.search(r"finds\s+all (\d+) targets\s+positionally mispaired", text).group(1))
    assert (
        mispaired
        == count
        == len(pd.read_parquet(folder / "runs/identity/profiles/euvs_official/metrics.parquet"))
    )
