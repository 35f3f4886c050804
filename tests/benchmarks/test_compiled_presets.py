"""``benchmarks/compiled_presets.py``'s orchestration (one process per case, a barrier, timing under a lock) and
``benchmarks/train_step.py``'s student objective, on the CPU with tiny models: the GPU numbers in
docs/performance.md rely on both."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import pytest
import torch

import benchmarks.common as common
from benchmarks.compiled_presets import CASES, build_case, run_driver, wait_for_siblings
from benchmarks.train_step import student_config
from setdiff_bench.models.setdiff.config_io import load_config
from setdiff_bench.models.setdiff.distill import check_student_config, load_teacher


def test_cases_restrict_attention_through_the_model_config() -> None:
    model = build_case(CASES["fast_view0"], torch.device("cpu"), torch.float32, "tiny_setdiff")
    assert model.config.set_attention == ("view",)
    assert (
        build_case(CASES["paper"], torch.device("cpu"), torch.float32, "tiny_setdiff").config.set_attention
        == ()
    )
    assert CASES["paper"].guidance == 2.0 and not CASES["paper"].unchunked
    assert all(CASES[name].guidance == 1.0 for name in ("fast", "fast_view0", "fast_view01"))


def test_barrier_counts_ready_and_failed_cases(tmp_path: Path) -> None:
    (tmp_path / "ready.a").touch()
    assert not wait_for_siblings(tmp_path, 2, time.monotonic() + 0.2)  # b neither ready nor failed
    (tmp_path / "failed.b").touch()
    assert wait_for_siblings(tmp_path, 2, time.monotonic() + 0.2)


def test_driver_times_each_case_alone_after_all_are_ready(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(common, "RESULTS", tmp_path)
    args = argparse.Namespace(
        cases="fast,difix",
        device="cpu",
        height=32,
        width=64,
        refs=1,
        targets=1,
        repeats=1,
        guidance=2.0,
        barrier_s=120.0,
        timeout_s=240.0,
        no_compile=True,
        small_config=True,
        out="presets",
    )
    payload = run_driver(args)
    assert set(payload["cases"]) == {"fast", "difix"}
    for row in payload["cases"].values():
        assert "failed" not in row, row
        assert row["timed_alone"] is True
        assert row["frames"] == 1 and row["total_ms_per_frame"] > 0
    assert payload["cases"]["fast"]["guidance_scale"] == 1.0
    assert (tmp_path / "presets.json").is_file()


def test_student_objective_trains_against_a_saved_teacher(tmp_path: Path) -> None:
    config = load_config("tiny_setdiff")
    student = student_config(config, tmp_path / "teacher")
    assert student.model.guidance_scale == 1.0 and student.model.geometry_dropout == 0.0
    assert student.train.distill_guidance_scale == config.model.guidance_scale
    check_student_config(student)
    teacher, scale = load_teacher(student)
    assert scale == config.model.guidance_scale
    assert not any(p.requires_grad for p in teacher.parameters())
