"""Before a run enhances anything: a packet too large for the memory is refused in one line, and a shipped
model run on data unlike its training data is named in one warning (issue 44)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.errors import OutOfDistributionWarning
from setdiff_bench.evaluation.preflight import packet_shapes, warn_out_of_distribution
from setdiff_bench.runtime.memory import MEMORY_LIMIT_ENV, parse_bytes
from tests.evaluation.run.store_fixtures import HEIGHT, WIDTH, StoreSpec, build_store, run_argv

#: A store of another dataset (DL3DV's name) at the fixtures' 48×32, unlike the shipped models' 256×144.
OTHER_DATA = StoreSpec(dataset="dl3dv", protocol="dl3dv", groups=("n3",), references=2, targets=2)


@pytest.fixture(scope="module")
def other_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_store(tmp_path_factory.mktemp("other") / "packets", OTHER_DATA)


@pytest.mark.parametrize("model", ["tiny_setdiff", "tiny_difix"])
def test_shipped_model_on_other_data_warns_once_naming_both(
    other_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], model: str
) -> None:
    method = model.removeprefix("tiny_")
    assert main(run_argv(method, other_store, tmp_path / "run", "--checkpoint", model)) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert lines == [
        f"setdiff-bench run: warning: {model} was trained on synthetic at 256×144; this store is dl3dv at "
        f"{WIDTH}×{HEIGHT}: its outputs may be worse than the input renders here (score them against the "
        "raw render, method identity)"
    ]


def test_no_warning_on_the_demo_data() -> None:
    """The demo's store (synthetic, 256×144, what the shipped models were trained on) gives no warning."""
    index = pd.DataFrame(
        {
            "packet_id": ["p", "p", "p"],
            "role": ["ref", "target", "target"],
            "dataset": ["synthetic"] * 3,
            "height": [144] * 3,
            "width": [256] * 3,
        }
    )
    enhancer = load_enhancer("setdiff", "tiny_setdiff", device="cpu")
    with warnings.catch_warnings():
        warnings.simplefilter("error", OutOfDistributionWarning)
        assert warn_out_of_distribution(enhancer, index, ["p"]) is None
    with pytest.warns(OutOfDistributionWarning, match="this store is synthetic at 512×288"):
        warn_out_of_distribution(enhancer, index.assign(height=288, width=512), ["p"])


def test_packet_too_large_is_refused_in_one_line_and_writes_nothing(
    other_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv(MEMORY_LIMIT_ENV, "1M")
    out = tmp_path / "run"
    assert main(run_argv("setdiff", other_store, out, "--checkpoint", "tiny_setdiff")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith(f"setdiff-bench run: error: {other_store}: enhancing packet ")
    assert f"(2 references + 2 targets of {WIDTH}x{HEIGHT}) with setdiff needs about " in err[0]
    assert "1 MB available; use fewer views per set (-o targets_per_set=M" in err[0]
    assert not out.exists()


def test_packet_shapes_counts_views_per_packet(other_store: Path) -> None:
    index = pd.read_parquet(other_store / "index.parquet")
    shapes = packet_shapes(index, sorted(set(index["packet_id"])))
    assert shapes[["references", "targets", "height", "width"]].drop_duplicates().values.tolist() == [
        [2, 2, HEIGHT, WIDTH]
    ]


@pytest.mark.parametrize(
    ("text", "expected"), [("1M", 1 << 20), ("2G", 2 << 30), ("512", 512), ("1.5GiB", 3 << 29), ("3kb", 3072)]
)
def test_parse_bytes(text: str, expected: int) -> None:
    assert parse_bytes(text) == expected


def test_run_records_peak_memory(other_store: Path, tmp_path: Path) -> None:
    """Every target row and the manifest carry the peak memory (CPU: the process's peak resident set, which
    holds at least the loaded model and the packet)."""
    import json

    out = tmp_path / "run"
    assert main(run_argv("difix", other_store, out, "--checkpoint", "tiny_difix")) == 0
    rows = pd.read_parquet(out / "metrics.parquet")
    assert (rows["peak_memory_mb"] > 100).all()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["timing"]["peak_memory_mb"] == rows["peak_memory_mb"].max()
