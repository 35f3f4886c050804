"""run.json names the SHA-256 of the weights and config behind ``--checkpoint``, and a resume with other
weights behind the same option is refused (it would report the old model's cells as the new one's)."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.io.run_layout import METRICS_FILE, RUN_FILE
from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from setdiff_bench.runtime.threads import torch_threads
from tests.models.setdiff_fixtures import perturbed_model


def _save(folder: Path, head_seed: int) -> Path:
    """A tiny SetDiff checkpoint whose UNet output head is drawn from ``head_seed``."""
    model, config = perturbed_model()
    with torch.no_grad():
        weight = model.unet.conv_out.weight
        weight.copy_(0.05 * torch.randn(weight.shape, generator=torch.Generator().manual_seed(head_seed)))
    return save_checkpoint(folder, model, config)


def test_run_json_names_the_checkpoint_files_and_refuses_other_weights(store: Path, tmp_path: Path) -> None:
    checkpoint = _save(tmp_path / "ckpt", head_seed=10)
    settings = RunSettings("setdiff", {"checkpoint": str(checkpoint)}, device="cpu")
    out = tmp_path / "run"
    with torch_threads(1):
        run_method(store, out, settings, progress=False)
    recorded = json.loads((out / RUN_FILE).read_text())["model_files"]
    expected = {
        name: hashlib.sha256((checkpoint / name).read_bytes()).hexdigest()
        for name in ("model.safetensors", "config.json")
    }
    assert recorded == expected

    # the same command resumes (nothing left to do) ...
    with torch_threads(1):
        assert run_method(store, out, settings, progress=False).merged
    # ... but other weights in the same folder (a retrained model) are refused, and the run is untouched
    metrics_before = (out / METRICS_FILE).read_bytes()
    _save(checkpoint, head_seed=11)
    with pytest.raises(UsageError, match=r"other model files \(their SHA-256 differ\)"):
        run_method(store, out, settings, progress=False)
    assert (out / METRICS_FILE).read_bytes() == metrics_before

    # a run.json written before the files were recorded cannot be trusted either
    identity = json.loads((out / RUN_FILE).read_text())
    del identity["model_files"]
    (out / RUN_FILE).write_text(json.dumps(identity))
    with pytest.raises(UsageError, match=r"were not recorded"):
        run_method(store, out, settings, progress=False)


def test_methods_without_weights_record_no_model_files(identity_run: Path) -> None:
    """identity has no fingerprint: its run.json is unchanged, so its older run folders still resume."""
    assert "model_files" not in json.loads((identity_run / RUN_FILE).read_text())
