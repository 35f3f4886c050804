"""Speed presets: ``paper`` runs the checkpoint as given, ``fast`` the shipped one-pass student that names
it as its teacher (found by manifest), one-pass checkpoints are their own ``fast``, and a two-pass model
without a student is refused in one line."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from setdiff_bench.enhancers.setdiff import fingerprint, speed_checkpoint
from setdiff_bench.errors import UsageError
from setdiff_bench.models.setdiff import packaged
from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from tests.models.setdiff_fixtures import perturbed_model


def ship(root: Path, name: str, guidance_scale: float, teacher: str | None = None) -> None:
    """A shipped-model folder: checkpoint + manifest (naming ``teacher`` when it is a student)."""
    model, config = perturbed_model({"guidance_scale": guidance_scale})
    config = replace(config, model=replace(config.model, guidance_scale=guidance_scale))
    save_checkpoint(root / name, model, config)
    manifest = {"format": "test"} | ({"distillation": {"teacher": teacher}} if teacher else {})
    (root / name / "manifest.json").write_text(json.dumps(manifest))


@pytest.fixture
def shipped(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "weights"
    ship(root, "teacher", 1.5)
    ship(root, "teacher_student", 1.0, teacher="teacher")
    ship(root, "lonely", 1.5)
    monkeypatch.setattr(packaged, "packaged_root", lambda: root)
    return root


def test_fast_runs_the_shipped_student_of_a_shipped_teacher(shipped: Path) -> None:
    assert speed_checkpoint("setdiff", "teacher", None) == "teacher"
    assert speed_checkpoint("setdiff", "teacher", "paper") == "teacher"
    assert speed_checkpoint("setdiff", "teacher", "fast") == "teacher_student"
    assert speed_checkpoint("setdiff", "teacher_student", "fast") == "teacher_student"  # one pass already
    assert fingerprint("teacher", speed="fast") == fingerprint("teacher_student")
    assert fingerprint("teacher", speed="fast") != fingerprint("teacher")


def test_fast_without_a_student_and_unknown_presets_are_refused(shipped: Path) -> None:
    with pytest.raises(UsageError, match="none ships for 'lonely'"):
        speed_checkpoint("setdiff", "lonely", "fast")
    with pytest.raises(UsageError, match="speed must be one of paper, fast"):
        speed_checkpoint("setdiff", "teacher", "ludicrous")
