"""The Python face (issue 38): ``import setdiff_bench`` stays cheap, every public name loads, and the
examples of ``docs/api.md`` run as written on a small generated packet store."""

from __future__ import annotations

import ast
import contextlib
import io
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import setdiff_bench as sb
from setdiff_bench.evaluation.run import RunSettings, run_method
from tests.evaluation.run.store_fixtures import StoreSpec, build_store

ROOT = Path(__file__).resolve().parents[2]
API_DOC = ROOT / "docs" / "api.md"


def python_blocks(path: Path) -> list[str]:
    """The fenced ``python`` code blocks of a Markdown file, in order."""
    return re.findall(r"```python\n(.*?)```", path.read_text(encoding="utf-8"), flags=re.S)


def test_import_loads_no_heavy_library() -> None:
    code = (
        "import json, sys; import setdiff_bench; "
        "print(json.dumps(sorted(m for m in ('torch', 'numpy', 'pandas', 'pyarrow') if m in sys.modules)))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(result.stdout) == []


def test_every_public_name_loads() -> None:
    public = set(sb.__all__) - {"SetDiffBenchError", "UsageError", "__version__"}
    assert public == set(sb._LAZY)
    for name in sorted(public):
        assert getattr(sb, name) is not None, name
    assert dir(sb) == sorted(sb.__all__)  # the documented API only: no Any, TYPE_CHECKING, errors, ...
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        sb.nothing  # noqa: B018


def test_the_documented_examples_run_as_written(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Both examples of docs/api.md, verbatim, in a folder holding ``runs/demo/work/packets``."""
    blocks = python_blocks(API_DOC)
    assert len(blocks) == 2
    three_lines = [line for line in blocks[0].splitlines() if line and not line.startswith("import ")]
    assert len(three_lines) == 3, three_lines
    build_store(tmp_path / "runs" / "demo" / "work" / "packets")
    monkeypatch.chdir(tmp_path)
    printed = []
    for block in blocks:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            exec(compile(block, str(API_DOC), "exec"), {"__name__": "__docs__"})
        printed.append(out.getvalue().strip())
    means = ast.literal_eval(printed[0])
    assert set(means) == {"psnr", "ssim", "lpips"} and means["psnr"] > 10
    assert (tmp_path / "runs" / "notebook" / "setdiff" / "metrics.parquet").is_file()
    assert "| setdiff |" in printed[1]


def test_run_scores_each_packet_with_score_packet(tmp_path: Path) -> None:
    """One implementation: ``run`` writes exactly what ``score_packet`` computes, packet by packet."""
    store_root = build_store(tmp_path / "packets", StoreSpec())
    result = run_method(store_root, tmp_path / "run", RunSettings("identity"), progress=False)
    assert result.merged
    import pandas as pd

    rows = pd.read_parquet(tmp_path / "run" / "metrics.parquet")
    store = sb.PacketStore(store_root)
    enhancer = sb.create_enhancer("identity")
    for packet_id in store.packet_ids("test"):
        scored = sb.score_packet(enhancer, store, packet_id)
        mine = rows[rows["packet_id"] == packet_id].sort_values("view")
        for metric in ("psnr", "ssim", "lpips"):
            assert mine[metric].tolist() == pytest.approx(list(scored.scores[metric]), abs=0, rel=0)


def test_errors_name_the_python_parameter(tmp_path: Path) -> None:
    store = sb.PacketStore(build_store(tmp_path / "packets"))
    enhancer = sb.create_enhancer("identity")
    with pytest.raises(sb.UsageError, match=r"^packet_id: no packet 'nope'"):
        sb.score_packet(enhancer, store, "nope")
    packet_id = store.packet_ids()[0]
    with pytest.raises(sb.UsageError, match=r"^metrics: unknown metric 'psnrr'") as error:
        sb.score_packet(enhancer, store, packet_id, metrics="psnrr")
    assert "--" not in str(error.value)
    with pytest.raises(sb.UsageError, match=r"^batch_size: "):
        sb.score_packet(enhancer, store, packet_id, batch_size=0)


def test_a_wrong_output_shape_is_refused(tmp_path: Path) -> None:
    store = sb.PacketStore(build_store(tmp_path / "packets"))

    class Cropping:
        name = "cropping"

        def enhance(self, packet: sb.Packet):  # type: ignore[no-untyped-def]
            return packet.targets.images[:, :, 1:]

    with pytest.raises(sb.EnhancerOutputError, match="expected"):
        sb.score_packet(Cropping(), store, store.packet_ids()[0])  # type: ignore[arg-type]


def test_a_source_checkout_works_without_an_install() -> None:
    """``PYTHONPATH=.`` on a machine where nothing is installed: the root's ``loaders/`` and ``protocols/`` load
    as ``setdiff_bench.loaders`` / ``.protocols`` (simulated by dropping the editable install's finder)."""
    code = (
        "import sys; "
        "sys.meta_path[:] = [f for f in sys.meta_path if 'editable' not in getattr(f, '__module__', '')]; "
        f"sys.path.insert(0, {str(ROOT)!r}); "
        "import setdiff_bench as sb, setdiff_bench.loaders as loaders, setdiff_bench.protocols as protocols; "
        "print(protocols.__file__); print(loaders.__file__); print(sb.load_protocol('dl3dv').name)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    protocols_file, loaders_file, name = result.stdout.split()
    assert Path(protocols_file) == ROOT / "protocols" / "__init__.py"
    assert Path(loaders_file) == ROOT / "loaders" / "__init__.py"
    assert name == "dl3dv"
