"""`setdiff-bench ablate geometry --variants none,both`: only the chosen variants are trained (None without
geometry, Both with C-maps and Plücker rays), each is run on the test split, and the table's cells are the
pooled means of those runs, with the paper's Both-vs-None comparison under it; with `--average 2
--guidance-scale 1` the trained variants are averaged and run at that scale."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.models.setdiff.checkpoint import resolve_checkpoint
from tests.models.setdiff_fixtures import STORE_TRAIN_CONFIG as CONFIG
from tests.models.setdiff_fixtures import write_store

METRICS = ("psnr", "ssim", "lpips")


def ablate_two_variants(tmp_path: Path) -> tuple[list[str], Path, Path]:
    """``ablate geometry --variants both,none`` on a tiny store, checked; returns ``(argv, out, work)``."""
    write_store(tmp_path / "packets")
    config = tmp_path / "tiny.toml"
    config.write_text(CONFIG.replace("checkpoint_every = 2", "checkpoint_every = 1"))
    out = tmp_path / "ablation"
    argv = ["ablate", "geometry", "--packets", str(tmp_path / "packets"), "--out", str(out)]
    argv += ["--config", str(config), "--variants", "both,none", "--device", "cpu", "--no-progress"]
    assert main(argv) == 0

    work = out / "work" / "ablation_geometry"
    assert sorted(p.name for p in (work / "checkpoints").iterdir()) == ["both", "none"]
    for variant, use_geometry in (("none", False), ("both", True)):
        saved = json.loads((resolve_checkpoint(work / "checkpoints" / variant) / "config.json").read_text())
        assert saved["model"]["use_geometry"] is use_geometry
        assert resolve_checkpoint(work / "checkpoints" / variant).name == "step-00000002"

    table = pd.read_parquet(out / "ablation_geometry.parquet").set_index("variant")
    assert list(table.index) == ["none", "both"]  # the paper's row order, whatever order was asked for
    for variant in ("none", "both"):
        metrics = pd.read_parquet(work / "runs" / variant / METRICS_FILE)
        assert len(metrics) == 3  # the test packet's three targets
        for metric in METRICS:
            assert abs(table.loc[variant, metric] - float(metrics[metric].mean())) < 1e-9

    markdown = (out / "ablation_geometry.md").read_text()
    assert "- PSNR: Both vs None " in markdown
    assert "--variants both,none" in markdown
    assert "| Both |" in markdown and "| None |" in markdown and "| Coordinate maps |" not in markdown
    return argv, out, work


def test_two_variants_are_trained_run_and_tabulated(tmp_path: Path) -> None:
    ablate_two_variants(tmp_path)


@pytest.mark.slow  # the trainings again, then their averages (averaged export: tests/models/test_packaged.py)
def test_averaged_variants_are_run_at_the_given_scale(tmp_path: Path) -> None:
    """Each variant as the mean of its two newest checkpoints (steps 1 and 2) at CFG scale 1: the trainings
    are done, so only the export and run stages run; the cells are those runs' pooled means."""
    argv, out, work = ablate_two_variants(tmp_path)
    assert main([*argv, "--average", "2", "--guidance-scale", "1"]) == 0
    table = pd.read_parquet(out / "ablation_geometry.parquet").set_index("variant")
    for variant in ("none", "both"):
        manifest = json.loads((work / "averaged2" / variant / "manifest.json").read_text())
        assert manifest["export"]["averaged_steps"] == [1, 2]
        run = json.loads((work / "runs" / "avg2_cfg1" / variant / "run.json").read_text())
        assert run["options"]["checkpoint"] == str(work / "averaged2" / variant)
        metrics = pd.read_parquet(work / "runs" / "avg2_cfg1" / variant / METRICS_FILE)
        for metric in METRICS:
            assert abs(table.loc[variant, metric] - float(metrics[metric].mean())) < 1e-9
    assert "--average 2" in (out / "ablation_geometry.md").read_text()


def test_variants_of_a_biased_config_bias_attention_only_where_they_see_c_maps() -> None:
    """The C-map attention bias is C-map geometry: None and Camera poses must train without it (else the
    'no geometry' row would still attend by C-map distance, and a biased config could not make a None row:
    the bias needs ``use_geometry``); the rows with C-maps keep the config's bias."""
    from setdiff_bench.models.setdiff.config import config_from_dict
    from setdiff_bench.models.setdiff.config_io import config_toml_data
    from setdiff_bench.reporting.ablation import GEOMETRY_VARIANTS

    biased = config_toml_data(
        Path(__file__).parents[3] / "benchmarks" / "configs" / "tiny_setdiff_cmap_bias_lowest.toml"
    )
    expected = {"none": "none", "cmap": "cmap_distance", "pose": "none", "both": "cmap_distance"}
    for variant in GEOMETRY_VARIANTS:
        model = config_from_dict({**biased, "model": {**biased["model"], **variant.overrides}}).model
        assert model.attention_bias == expected[variant.key], variant.key
        assert model.attention_bias_layers == "lowest"
