"""`setdiff-bench ablate setsize` with two trained models (two training seeds): each cell is the mean of the
two models' pooled means, each model's values and paired gains are kept, and the spread is printed."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import torch

from setdiff_bench.cli.main import main
from setdiff_bench.evaluation.paths import METRICS_FILE
from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from tests.models.test_checkpoint import perturbed_model

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
