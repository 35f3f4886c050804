"""``benchmarks/output_sharpness.py``: the Laplacian energy on images whose Laplacian is known by hand."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.output_sharpness import laplacian_energy, main, summary
from tests.models.setdiff_fixtures import write_store


def grey(values: np.ndarray) -> np.ndarray:
    """``(H, W)`` → ``(H, W, 3)`` with equal channels (luma = the value, the weights sum to 1)."""
    return np.repeat(values[..., None], 3, axis=2).astype(np.float32)


def test_a_checkerboard_has_eight_times_its_amplitude() -> None:
    """c ± h alternating: every pixel's four neighbours have the other sign, so |4·(c ∓ h) − 4·(c ± h)| = 8h
    (also at the border, which OpenCV reflects without repeating the edge pixel)."""
    rows, cols = np.indices((12, 17))
    board = 0.5 + 0.05 * np.where((rows + cols) % 2 == 0, 1.0, -1.0)
    assert laplacian_energy(grey(board)) == pytest.approx(8 * 0.05, rel=1e-5)


def test_flat_and_linear_images_have_none_inside() -> None:
    """A ramp's Laplacian is zero inside; at the two side columns the reflected neighbour gives |2·step|."""
    assert laplacian_energy(grey(np.full((9, 11), 0.3))) == 0.0
    step = 0.08
    ramp = np.tile(0.1 + step * np.arange(11), (9, 1))
    assert laplacian_energy(grey(ramp)) == pytest.approx(2 * 9 * 2 * step / (9 * 11), rel=1e-4)


def test_restored_share_is_the_fraction_of_the_gap_closed() -> None:
    records = [
        {"ground_truth": 0.03, "render": 0.01, "a": 0.02, "b": 0.04},
        {"ground_truth": 0.05, "render": 0.03, "a": 0.04, "b": 0.06},
    ]
    result = summary(records, ["a", "b"])
    assert result["a_restored"] == pytest.approx(0.5)
    assert result["b_restored"] == pytest.approx(1.5)
    assert result["targets"] == 2
    assert math.isclose(result["ground_truth"], 0.04)


@pytest.mark.parametrize("missing", ["no_store", "nowhere"])
def test_a_missing_store_or_run_folder_is_one_line_and_exit_2(
    missing: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``no_store``: the packet store is missing; ``nowhere``: the store exists, the run folder does not."""
    packets = tmp_path / "packets"
    if missing == "nowhere":
        write_store(packets)
    out = tmp_path / "sharpness.json"
    argv = ["output_sharpness.py", "--packets", str(packets), "--run", f"a={tmp_path / 'nowhere'}"]
    monkeypatch.setattr(sys, "argv", [*argv, "--out", str(out)])
    assert main() == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(packets if missing == "no_store" else "nowhere") in err, err
    assert not out.exists()
