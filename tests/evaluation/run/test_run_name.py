"""``run --name``: a display name for a run, recorded in ``run.json`` and the manifest and carried by every row,
so that two ``precomputed`` methods (two folders of external images) share one leaderboard."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.run import RunSettings, claimed_label, run_method
from setdiff_bench.io.run_layout import IMAGES_DIR, MANIFEST_FILE, METRICS_FILE, RUN_FILE
from tests.evaluation.run.store_fixtures import leaderboard_argv, run_argv


def darkened_copy(images: Path, out: Path, factor: float) -> Path:
    """Every PNG of ``images`` multiplied by ``factor`` (an external method's outputs)."""
    for png in images.rglob("*.png"):
        target = out / png.relative_to(images)
        target.parent.mkdir(parents=True, exist_ok=True)
        pixels = cv2.imread(str(png))
        cv2.imwrite(str(target), np.rint(pixels * factor).astype(np.uint8))
    return out


def test_two_named_precomputed_runs_share_one_leaderboard(
    store: Path,
    identity_run: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    same = tmp_path / "same"
    shutil.copytree(identity_run / IMAGES_DIR, same)
    dark = darkened_copy(identity_run / IMAGES_DIR, tmp_path / "dark", 0.5)
    monkeypatch.chdir(tmp_path)  # no --out: each run's default folder is named after the run
    runs = tmp_path / "results" / "runs" / store.name
    shutil.copytree(identity_run, runs / "identity")
    for name, source in (("copied", same), ("darker", dark)):
        argv = ["run", "--method", "precomputed", "--packets", str(store), "--no-progress"]
        assert main([*argv, "--from", str(source), "--name", name]) == 0
        assert capsys.readouterr().out.startswith(f"{name} [0/1]: enhanced 4 packets")

    copied = pd.read_parquet(runs / "copied" / METRICS_FILE)
    identity = pd.read_parquet(runs / "identity" / METRICS_FILE)
    assert set(copied["method"]) == {"copied"}
    # the name changes the label, not the numbers: a copy of identity's images scores as identity did
    np.testing.assert_array_equal(copied["psnr"].to_numpy(), identity["psnr"].to_numpy())
    manifest = json.loads((runs / "darker" / MANIFEST_FILE).read_text())
    assert manifest["method"]["name"] == "darker" and manifest["method"]["id"] == "precomputed"
    run_file = runs / "darker" / RUN_FILE
    assert json.loads(run_file.read_text())["name"] == "darker"
    assert claimed_label(run_file) == "darker" and claimed_label(runs / "identity" / RUN_FILE) == "identity"
    # an unnamed run's run.json is as before (no "name"), so runs made before names existed still resume
    assert "name" not in json.loads((runs / "identity" / RUN_FILE).read_text())
    # the name is part of the run's settings: the same run without it is another run
    unnamed = RunSettings("precomputed", {"source": str(dark.resolve())})
    assert unnamed.label == "precomputed" and RunSettings("precomputed", name="darker").label == "darker"
    with pytest.raises(UsageError, match=r"other settings \(name differ\)"):
        run_method(store, runs / "darker", unnamed, progress=False)

    assert main(leaderboard_argv("synthetic", runs, tmp_path / "tables", "--format", "parquet")) == 0
    table = pd.read_parquet(tmp_path / "tables" / "synthetic.parquet")
    assert sorted(set(table["label"])) == ["copied", "darker", "identity"]
    psnr = table[(table["metric"] == "psnr") & (table["block"] == "lane+1")].set_index("label")["value"]
    assert psnr["copied"] == pytest.approx(psnr["identity"]) and psnr["darker"] < psnr["identity"] - 1.0


@pytest.mark.parametrize(
    ("name", "problem"),
    [
        ("my method", "a run's name is a letter or digit followed by"),
        ("../up", "a run's name is a letter or digit followed by"),
        ("setdiff", "'setdiff' is the name of another method"),
    ],
)
def test_bad_names_are_refused_before_anything_is_written(
    store: Path,
    identity_run: Path,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    name: str,
    problem: str,
) -> None:
    out = tmp_path / "out"
    argv = run_argv("precomputed", store, out, "--from", str(identity_run), "--name", name)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("setdiff-bench run: error: --name ") and problem in err[0], err
    assert not out.exists()
