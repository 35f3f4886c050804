"""FID / KID of a run's enhanced targets against the recorded frames (issue 41), through the library and
the ``run`` / ``evaluate --inception FILE`` doors.

The library test uses a stand-in feature network (channel means) and recomputes every value
independently: images read with PIL, the recorded set from the store's index, FID with scipy's
``sqrtm``, KID with explicit loops.  The CLI tests use a random-weight FID Inception-v3 saved in the
pytorch-fid state-dict format.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.linalg
import torch
from PIL import Image

from setdiff_bench.cli.main import main
from setdiff_bench.evaluation.distribution_scoring import (
    DISTRIBUTION_FILE,
    DISTRIBUTION_INFO_FILE,
    score_distribution,
)
from setdiff_bench.metrics.inception import FIDInceptionV3
from setdiff_bench.runtime.threads import torch_threads
from tests.metrics.inception_fixtures import random_inception, save_inception


class ChannelMeans(torch.nn.Module):
    """``(B, 3, H, W)`` → ``(B, 3)`` channel means: a feature network whose output is known by hand."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x.mean(dim=(2, 3))


def _means(path: Path) -> np.ndarray:
    pixels = np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255.0
    return pixels.mean(axis=(0, 1))


def _fid_scipy(a: np.ndarray, b: np.ndarray) -> float:
    s1, s2 = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    d = a.mean(0) - b.mean(0)
    return float(d @ d + np.trace(s1) + np.trace(s2) - 2 * np.trace(scipy.linalg.sqrtm(s1 @ s2)).real)


def _fid_gram(a: np.ndarray, b: np.ndarray) -> float:
    """FID of few features in many dimensions, where scipy's ``sqrtm`` of a singular 2048×2048 product is slow
    and inaccurate: ``tr (Σ₁Σ₂)^½`` is the sum of the roots of the eigenvalues of the ``(m, m)`` symmetric
    matrix ``A Bᵀ B Aᵀ / ((m−1)(n−1))`` (A, B centred), which shares the non-zero eigenvalues of ``Σ₁Σ₂``."""
    m, n = len(a), len(b)
    ca, cb = a - a.mean(0), b - b.mean(0)
    cross = ca @ cb.T
    values = np.linalg.eigvalsh(cross @ cross.T / ((m - 1) * (n - 1)))
    d = a.mean(0) - b.mean(0)
    return float(
        d @ d + (ca**2).sum() / (m - 1) + (cb**2).sum() / (n - 1) - 2 * np.sqrt(values.clip(0)).sum()
    )


def _kid_loops(a: np.ndarray, b: np.ndarray) -> float:
    k = lambda x, y: (float(x @ y) / len(x) + 1.0) ** 3  # noqa: E731
    m, n = len(a), len(b)
    xx = sum(k(a[i], a[j]) for i in range(m) for j in range(m) if i != j) / (m * (m - 1))
    yy = sum(k(b[i], b[j]) for i in range(n) for j in range(n) if i != j) / (n * (n - 1))
    xy = sum(k(a[i], b[j]) for i in range(m) for j in range(n)) / (m * n)
    return xx + yy - 2 * xy


def test_blocks_score_against_the_recorded_frames(store: Path, identity_run: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(identity_run, run)
    lines: list[str] = []
    table = score_distribution(
        run,
        store,
        ChannelMeans(),
        weights_sha256="abc",
        weights_file="/m/pt_inception.pth",
        progress=lines.append,
    )
    assert (run / DISTRIBUTION_FILE).is_file() and (run / DISTRIBUTION_INFO_FILE).is_file()
    info = json.loads((run / DISTRIBUTION_INFO_FILE).read_text())
    assert (info["inception_sha256"], info["inception_file"]) == (
        "abc",
        "pt_inception.pth",
    )  # the name, no folder
    assert pd.read_parquet(run / DISTRIBUTION_FILE).equals(table)
    index = pd.read_parquet(store / "index.parquet")
    assert sorted(table["group"]) == sorted(set(index["group"]))
    for row in table.to_dict("records"):
        enhanced = sorted((run / "images" / row["protocol"] / row["group"]).rglob("*.png"))
        refs = index[(index["role"] == "ref") & (index["group"] == row["group"])]
        refs = refs.drop_duplicates(["scene", "frame"])
        a = np.stack([_means(p) for p in enhanced])
        b = np.stack([_means(store / p) for p in refs["image"]])
        assert (row["enhanced"], row["recorded"], row["scenes"]) == (len(a), len(b), 2)
        assert row["fid"] == pytest.approx(_fid_scipy(a, b), rel=1e-6, abs=1e-9)
        assert row["kid"] == pytest.approx(_kid_loops(a, b), rel=1e-6, abs=1e-9)  # float32 features
        assert row["kid_std"] == 0.0 and row["kid_subsets"] == 1 and pd.isna(row["kid_subset_size"])
    assert len(lines) == len(table) and "FID" in lines[0] and "recorded frames" in lines[0]


@pytest.fixture(scope="module")
def inception_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A random-weight FID Inception-v3 in pytorch-fid's format (:mod:`tests.metrics.inception_fixtures`)."""
    return save_inception(random_inception(), tmp_path_factory.mktemp("inception"))


def _pixels(path: Path) -> torch.Tensor:
    """``(3, H, W)`` float32 in [0, 1], read with PIL."""
    array = np.asarray(Image.open(path).convert("RGB"), dtype=np.float32) / 255.0
    return torch.from_numpy(array).permute(2, 0, 1)


def run_with_inception(store: Path, out: Path, inception: Path) -> list[str]:
    """``run --method identity`` of ``store`` into ``out``, scoring FID / KID with the weights ``inception``."""
    words = ["run", "--method", "identity", "--packets", str(store), "--out", str(out), "--no-progress"]
    return [*words, "--inception", str(inception)]


def test_run_with_inception_writes_the_distribution_table(
    store: Path, inception_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "identity"
    with torch_threads(1):
        code = main(run_with_inception(store, out, inception_file))
    assert code == 0
    printed = capsys.readouterr().out
    assert f"distribution: {out / DISTRIBUTION_FILE}" in printed
    table = pd.read_parquet(out / DISTRIBUTION_FILE)
    assert len(table) == 2 and (table["enhanced"] == 6).all() and (table["recorded"] == 4).all()
    # every block recomputed: PIL-read images through the saved network called directly (features well away
    # from zero), FID through the Gram matrix's eigenvalues and KID with loops
    model = FIDInceptionV3().eval()
    model.load_state_dict(torch.load(inception_file, weights_only=True))
    index = pd.read_parquet(store / "index.parquet")
    for row in table.to_dict("records"):
        enhanced = sorted((out / "images" / row["protocol"] / row["group"]).rglob("*.png"))
        refs = index[(index["role"] == "ref") & (index["group"] == row["group"])].drop_duplicates(
            ["scene", "frame"]
        )
        with torch_threads(1), torch.no_grad():
            a = model(torch.stack([_pixels(p) for p in enhanced])).double().numpy()
            b = model(torch.stack([_pixels(store / p) for p in refs["image"]])).double().numpy()
        assert np.abs(a).mean() > 1e-2 and np.abs(b).mean() > 1e-2
        assert _fid_gram(a, b) > 1e-2 and abs(_kid_loops(a, b)) > 1e-4
        assert row["fid"] == pytest.approx(_fid_gram(a, b), rel=1e-4)
        assert row["kid"] == pytest.approx(_kid_loops(a, b), rel=1e-4)


def test_missing_inception_file_is_one_line_and_nothing_is_written(
    store: Path, identity_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "never"
    code = main(run_with_inception(store, out, tmp_path / "absent.pth"))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not out.exists()
    assert err[0].startswith(
        f"setdiff-bench run: error: {tmp_path / 'absent.pth'}: Inception weights file not found"
    )
    run = tmp_path / "run"
    shutil.copytree(identity_run, run)
    code = main(["evaluate", str(run), "--packets", str(store), "--inception", str(tmp_path / "absent.pth")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "Inception weights file not found" in err[0]
    assert not (run / DISTRIBUTION_FILE).exists() and not (run / "profiles").exists()


def test_evaluate_with_inception(
    store: Path, identity_run: Path, inception_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = tmp_path / "run"
    shutil.copytree(identity_run, run)
    with torch_threads(1):
        code = main(
            [
                "evaluate",
                str(run),
                "--packets",
                str(store),
                "--no-progress",
                "--inception",
                str(inception_file),
            ]
        )
    assert code == 0
    assert f"distribution: {run / DISTRIBUTION_FILE}" in capsys.readouterr().out
    assert len(pd.read_parquet(run / DISTRIBUTION_FILE)) == 2


def test_fid_and_kid_are_not_run_metrics(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        [
            "run",
            "--method",
            "identity",
            "--packets",
            str(store),
            "--out",
            str(tmp_path / "x"),
            "--metrics",
            "fid",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "fid is a distribution metric; it is enabled with --inception FILE" in err
