"""``run`` on novel-trajectory packets (issue 41): the paired metrics are skipped and named, the enhanced
frames are written, and FID / KID (a random-weight Inception-v3 in pytorch-fid's format) score them
against the recorded frames.

FID is checked against a closed form for few samples: with centred features ``A`` (m × D) and ``B``
(n × D), ``Σ₁ = AᵀA/(m−1)``, ``Σ₂ = BᵀB/(n−1)`` and the non-zero eigenvalues of ``Σ₁Σ₂`` are those of
``(A Bᵀ)(B Aᵀ)/((m−1)(n−1))``, so ``tr (Σ₁^½ Σ₂ Σ₁^½)^½`` is the nuclear norm of ``A Bᵀ`` over
``√((m−1)(n−1))``.  KID is the unbiased MMD² with the kernel ``(xᵀy/D + 1)³``, written as loops.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from PIL import Image

from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.base import create_enhancer
from setdiff_bench.evaluation.distribution_scoring import score_distribution
from setdiff_bench.evaluation.packet_scoring import score_packet
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.metrics.inception import load_inception
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.runtime.threads import torch_threads
from tests.packets.packet_fixtures import StreetScene
from tests.packets.trajectory.conftest import GROUPS, SHIFTS

SKIPPED_LINE = (
    "skipped psnr, ssim, lpips for 8 target(s) without ground truth (groups shift-3m, shift-6m): "
    "novel-trajectory views are scored by FID / KID (--inception FILE)"
)


def _tensor(path: Path) -> torch.Tensor:
    return torch.from_numpy(np.asarray(Image.open(path).convert("RGB"), dtype=np.float32) / 255.0).permute(
        2, 0, 1
    )


def _fid(a: np.ndarray, b: np.ndarray) -> float:
    m, n = len(a), len(b)
    ca, cb = a - a.mean(0), b - b.mean(0)
    trace_root = np.linalg.svd(ca @ cb.T, compute_uv=False).sum() / np.sqrt((m - 1) * (n - 1))
    mean_term = float(np.sum((a.mean(0) - b.mean(0)) ** 2))
    return mean_term + (ca**2).sum() / (m - 1) + (cb**2).sum() / (n - 1) - 2 * trace_root


def _kid(a: np.ndarray, b: np.ndarray) -> float:
    k = lambda x, y: (float(x @ y) / len(x) + 1.0) ** 3  # noqa: E731
    m, n = len(a), len(b)
    xx = sum(k(a[i], a[j]) for i in range(m) for j in range(m) if i != j) / (m * (m - 1))
    yy = sum(k(b[i], b[j]) for i in range(n) for j in range(n) if i != j) / (n * (n - 1))
    xy = sum(k(a[i], b[j]) for i in range(m) for j in range(n)) / (m * n)
    return xx + yy - 2 * xy


def _run(method: str, store: Path, out: Path, *extra: str) -> int:
    with torch_threads(1):
        return main(
            ["run", "--method", method, "--packets", str(store), "--out", str(out), "--no-progress", *extra]
        )


def _check_distribution(out: Path, store: Path, inception_file: Path | None) -> pd.DataFrame:
    """The distribution table's blocks and set sizes; with ``inception_file``, FID / KID of every shift block
    recomputed from PIL-read images and the network called directly."""
    table = pd.read_parquet(out / "distribution.parquet")
    assert sorted(table["group"]) == sorted(GROUPS)
    assert (table["enhanced"] == 4).all() and (table["recorded"] == 4).all() and (table["scenes"] == 1).all()
    if inception_file is None:
        return table
    model = load_inception(inception_file)
    index = pd.read_parquet(store / "index.parquet")
    refs = index[index["role"] == "ref"]
    # the recorded frames are the same 4 fit frames in both blocks: their features are computed once
    recorded = sorted({str(store / p) for p in refs["image"]}, key=lambda p: p)
    frames = {str(store / p): f for p, f in zip(refs["image"], refs["frame"], strict=True)}
    with torch.no_grad():
        unique = dict(zip(sorted({frames[p] for p in recorded}), range(4), strict=True))
        first = {frames[p]: p for p in recorded}
        b_all = model(torch.stack([_tensor(Path(first[f])) for f in unique])).double().numpy()
    for row in table.to_dict("records"):
        enhanced = sorted((out / "images" / "synthetic" / row["group"] / "street_00").glob("*.png"))
        chosen = refs[refs["group"] == row["group"]]
        b = b_all[[unique[f] for f in chosen["frame"]]]
        with torch.no_grad():
            a = model(torch.stack([_tensor(p) for p in enhanced])).double().numpy()
        assert _fid(a, b) > 1e-3 and abs(_kid(a, b)) > 1e-6  # features that tell the sets apart
        assert row["fid"] == pytest.approx(_fid(a, b), rel=1e-4)
        assert row["kid"] == pytest.approx(_kid(a, b), rel=1e-4)
    return table


def test_identity_skips_the_paired_metrics_and_scores_fid_kid(
    shifted_store: Path, inception_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "identity"
    assert _run("identity", shifted_store, out, "--inception", str(inception_file)) == 0
    printed = capsys.readouterr().out.splitlines()
    assert [line for line in printed if line.startswith("skipped")] == [
        SKIPPED_LINE.replace("FID / KID (--inception FILE)", "FID / KID below")
    ]
    metrics = pd.read_parquet(out / "metrics.parquet")
    assert len(metrics) == 8 and metrics[["psnr", "ssim", "lpips"]].isna().all().all()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["skipped"] == {
        "metrics": ["psnr", "ssim", "lpips"],
        "targets": 8,
        "groups": ["shift-3m", "shift-6m"],
        "reason": "no ground truth (novel-trajectory targets); their metric columns are null",
    }
    index = pd.read_parquet(shifted_store / "index.parquet").query("role == 'target'")
    renders = dict(zip(index["frame"], index["image"], strict=True))
    for row in metrics.to_dict("records"):  # identity writes the render itself
        assert np.array_equal(_tensor(out / row["image"]), _tensor(shifted_store / renders[row["frame"]]))
    _check_distribution(out, shifted_store, inception_file)


class ChannelMeans(torch.nn.Module):
    """``(B, 3, H, W)`` → ``(B, 3)`` channel means: a feature network whose output is known by hand."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x.mean(dim=(2, 3))


def test_difix_on_lane_shifts(
    shifted_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The shipped tiny DiFix enhances the shift packets; FID / KID of its frames with a stand-in feature
    network (channel means: the Inception path costs two 2048² eigendecompositions per block, and is
    covered by the identity test)."""
    out = tmp_path / "difix"
    assert _run("difix", shifted_store, out, "--checkpoint", "tiny_difix") == 0
    assert SKIPPED_LINE in capsys.readouterr().out.splitlines()
    metrics = pd.read_parquet(out / "metrics.parquet")
    assert len(metrics) == 8 and metrics[["psnr", "ssim", "lpips"]].isna().all().all()
    index = pd.read_parquet(shifted_store / "index.parquet").query("role == 'target'")
    renders = dict(zip(index["frame"], index["image"], strict=True))
    changed = 0
    for row in metrics.to_dict("records"):
        assert Image.open(out / row["image"]).size == (48, 32)
        changed += not np.array_equal(
            _tensor(out / row["image"]), _tensor(shifted_store / renders[row["frame"]])
        )
    assert changed == 8  # DiFix changed every render
    with torch_threads(1):
        table = score_distribution(out, shifted_store, ChannelMeans())
    refs = pd.read_parquet(shifted_store / "index.parquet").query("role == 'ref'")
    for row in table.to_dict("records"):
        enhanced = sorted((out / "images" / "synthetic" / row["group"] / "street_00").glob("*.png"))
        a = np.stack([_tensor(p).double().mean(dim=(1, 2)).numpy() for p in enhanced])
        recorded = refs[refs["group"] == row["group"]]["image"]
        b = np.stack([_tensor(shifted_store / p).double().mean(dim=(1, 2)).numpy() for p in recorded])
        assert (row["enhanced"], row["recorded"]) == (4, 4)
        assert row["fid"] == pytest.approx(_fid(a, b), rel=1e-5, abs=1e-9)
        assert row["kid"] == pytest.approx(_kid(a, b), rel=1e-5, abs=1e-9)


def test_score_packet_names_what_it_skipped(shifted_store: Path) -> None:
    with torch_threads(1):
        result = score_packet(
            create_enhancer("identity"), shifted_store, "synthetic__street-00__shift-3m__0000"
        )
    assert result.skipped == ("psnr", "ssim", "lpips") and result.means() == {}
    assert all(np.isnan(values).all() and len(values) == 4 for values in result.scores.values())
    assert tuple(result.enhanced.shape) == (4, 3, 32, 48)


def test_warp_error_takes_the_render_flow_without_ground_truth(shifted_store: Path, tmp_path: Path) -> None:
    """``--warp on`` scores each shift's time-ordered targets as a sequence of its own, with the flow of
    their renders (tests/evaluation/run/test_render_flow_warp.py checks the values); only PSNR is named as skipped."""
    settings = RunSettings("identity", metrics=("psnr",), warp="on", flow_method="dis", warp_cache=None)
    with torch_threads(1):
        result = run_method(shifted_store, tmp_path / "run", settings, progress=False)
    assert result.merged and result.skipped_metrics is not None
    assert result.skipped_metrics.metrics == ("psnr",) and result.skipped_metrics.targets == 8
    sequences = pd.read_parquet(tmp_path / "run" / "sequences.parquet")
    assert sorted(sequences["group"]) == sorted(GROUPS) and set(sequences["flow_source"]) == {"render"}
    assert (sequences["frames"] == 4).all() and sequences["warp"].notna().all()


def test_a_mixed_store_scores_its_ground_truth_as_before(
    street: tuple[Path, StreetScene], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Protocol packets and lane-shift packets in one store: the protocol groups' rows equal those of a run
    on the protocol packets alone; the shift rows are null and named."""
    root, _ = street
    plain, mixed = tmp_path / "plain", tmp_path / "mixed"
    with torch_threads(1):
        prepare("synthetic", root, plain, fits=root, progress=False)
        shutil.copytree(plain, mixed)
        prepare("synthetic", root, mixed, fits=root, progress=False, trajectories=SHIFTS[:1])
    assert _run("identity", plain, tmp_path / "a", "--split", "all", "--warp-cache", "none") == 0
    assert "skipped" not in capsys.readouterr().out
    assert "skipped" not in json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert _run("identity", mixed, tmp_path / "b", "--split", "all", "--warp-cache", "none") == 0
    assert (
        "skipped psnr, ssim, lpips for 4 target(s) without ground truth (groups shift-3m)"
        in capsys.readouterr().out
    )
    drop = ["ms_per_frame", "peak_memory_mb"]
    a = pd.read_parquet(tmp_path / "a" / "metrics.parquet").drop(columns=drop)
    b = pd.read_parquet(tmp_path / "b" / "metrics.parquet").drop(columns=drop)
    assert b[b["group"] != "shift-3m"].reset_index(drop=True).equals(a)
    assert b.loc[b["group"] == "shift-3m", ["psnr", "ssim", "lpips"]].isna().all().all()
    assert a["psnr"].notna().all()


def test_evaluate_says_a_trajectory_run_has_no_profile_metric(
    shifted_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    with torch_threads(1):
        run_method(shifted_store, run, RunSettings("identity", metrics=("psnr",)), progress=False)
    code = main(["evaluate", str(run), "--packets", str(shifted_store), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err == [
        f"setdiff-bench evaluate: error: {run}: every target of this run is a novel-trajectory view without "
        "ground truth: no profile metric applies; pass --inception FILE for FID / KID"
    ]
    assert not (run / "profiles").exists()
