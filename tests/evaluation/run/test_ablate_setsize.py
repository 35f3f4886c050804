"""`setdiff-bench ablate setsize` with two trained models (two training seeds): each cell is the mean of the
two models' pooled means, each model's values and paired gains are kept, and the spread is printed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import torch

from setdiff_bench.cli.main import main
from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from tests.models.setdiff_fixtures import perturbed_model

METRICS = ("psnr", "ssim", "lpips")


def _two_models(root: Path) -> list[Path]:
    """Two tiny SetDiff checkpoints that differ in their output head (as two training seeds would)."""
    folders = []
    for seed in (0, 1):
        model, config = perturbed_model()
        with torch.no_grad():
            generator = torch.Generator().manual_seed(10 + seed)
            weight = model.unet.conv_out.weight
            weight.copy_(0.05 * torch.randn(weight.shape, generator=generator))
        folders.append(save_checkpoint(root / f"seed{seed}", model, config))
    return folders


def test_two_models_give_means_spread_and_per_model_values(store: Path, tmp_path: Path) -> None:
    checkpoints = _two_models(tmp_path / "ckpt")
    out = tmp_path / "ablation"
    argv = ["ablate", "setsize", "--packets", str(store), "--out", str(out), "--sizes", "1+1,2+1"]
    argv += [part for c in checkpoints for part in ("--checkpoint", str(c))]
    assert main([*argv, "--device", "cpu", "--no-progress"]) == 0

    # every model's pooled means, read back from its own runs with pandas
    own: dict[tuple[int, str], dict[str, float]] = {}
    for index in (0, 1):
        for size in ("1+1", "2+1"):
            metrics = pd.read_parquet(
                out / "work" / "ablation_setsize" / "runs" / f"model{index}" / size / METRICS_FILE
            )
            assert len(metrics) == 12  # 2 scenes x 2 groups x 3 targets, the same targets at every size
            own[(index, size)] = {m: float(metrics[m].mean()) for m in METRICS}
    assert own[(0, "2+1")]["psnr"] != own[(1, "2+1")]["psnr"]  # the two models differ

    table = pd.read_parquet(out / "ablation_setsize.parquet").set_index("metric")
    for metric, label in zip(METRICS, ("PSNR", "SSIM", "LPIPS")):
        for size, column in (("1+1", "1 + 1"), ("2+1", "2 + 1")):
            mean = (own[(0, size)][metric] + own[(1, size)][metric]) / 2
            assert abs(table.loc[label, column] - mean) < 1e-9

    per_model = pd.read_parquet(out / "ablation_setsize_per_model.parquet")
    assert len(per_model) == 2 * 2 * 3
    row = per_model[(per_model["model"] == str(checkpoints[1])) & (per_model["row"] == "2 + 1")]
    assert abs(float(row.loc[row["metric"] == "PSNR", "value"].iloc[0]) - own[(1, "2+1")]["psnr"]) < 1e-9

    markdown = (out / "ablation_setsize.md").read_text()
    assert "Each cell is the mean over 2 trained models" in markdown
    spread = abs(own[(0, "1+1")]["psnr"] - own[(1, "1+1")]["psnr"])
    assert f"PSNR spread (max − min over models): 1 + 1 {spread:.3f}" in markdown
    assert f"--checkpoint {checkpoints[0]} --checkpoint {checkpoints[1]}" in markdown


def test_guidance_scale_reaches_every_run(store: Path, tmp_path: Path) -> None:
    """`--guidance-scale 1` runs the model at that scale (not its checkpoint's 2.0) in runs/cfg1/: the cell
    equals a plain `run -o guidance_scale=1` of the same model, and differs from the checkpoint's scale."""
    checkpoint = _two_models(tmp_path / "ckpt")[0]
    out = tmp_path / "ablation"
    argv = ["ablate", "setsize", "--packets", str(store), "--out", str(out), "--sizes", "1+1"]
    argv += ["--checkpoint", str(checkpoint), "--device", "cpu", "--no-progress", "--guidance-scale", "1"]
    assert main(argv) == 0
    direct = tmp_path / "direct"
    run = ["run", "--method", "setdiff", "--checkpoint", str(checkpoint), "--packets", str(store)]
    run += ["--split", "test", "--device", "cpu", "--no-progress", "-o", "max_references=1"]
    run += ["-o", "targets_per_set=1"]
    assert main([*run, "--out", str(direct / "cfg1"), "-o", "guidance_scale=1"]) == 0
    assert main([*run, "--out", str(direct / "own")]) == 0
    ablated = pd.read_parquet(out / "work" / "ablation_setsize" / "runs" / "cfg1" / "1+1" / METRICS_FILE)
    at_one = pd.read_parquet(direct / "cfg1" / METRICS_FILE)
    own = pd.read_parquet(direct / "own" / METRICS_FILE)
    table = pd.read_parquet(out / "ablation_setsize.parquet").set_index("metric")
    for metric, label in zip(METRICS, ("PSNR", "SSIM", "LPIPS")):
        assert abs(table.loc[label, "1 + 1"] - float(at_one[metric].mean())) < 1e-9
        assert float(ablated[metric].mean()) == float(at_one[metric].mean())
    assert float(own["psnr"].mean()) != float(at_one["psnr"].mean())
    assert "--guidance-scale 1" in (out / "ablation_setsize.md").read_text()


def test_bad_guidance_scale_is_refused_before_any_run(
    store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ablation"
    argv = ["ablate", "setsize", "--packets", str(store), "--out", str(out), "--checkpoint", str(tmp_path)]
    assert main([*argv, "--guidance-scale", "-2", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--guidance-scale" in err and "-2" in err
    assert not out.exists()
