"""What a refit's manifest says it cost, for the refit itself and for one of its snapshots."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.io.refit_layout import refit_cost, snapshot_folder, snapshot_of

#: A progressive refit of 300 steps (updates before steps 1, 101, 201) that took 100 s: 10 s set-up, 60 s of
#: steps, 30 s of updates (24 s inside the enhancer), with snapshots after 100 and 200 steps.
MANIFEST = {
    "format": "setdiff-refit/1",
    "time": {
        "wall_s": 100.0,
        "steps_s": 60.0,
        "updates_s": 30.0,
        "enhance_s": 24.0,
        "s_per_step": 0.2,
        "steps_run": 300,
    },
    "updates": 3,
    "peak_memory_mb": 900.0,
    "enhancer": {"method": "setdiff"},
    "schedule": {"schedule": "progressive", "steps": 300, "update_every": 100},
    "ply": {"sha256": "f" * 64},
    "snapshots": [{"step": 100, "sha256": "a" * 64}, {"step": 200, "sha256": "b" * 64}],
}


@pytest.fixture
def out(tmp_path: Path) -> Path:
    (tmp_path / "refit" / "scene_a").mkdir(parents=True)
    (tmp_path / "refit" / "scene_a" / "lane0.refit.json").write_text(json.dumps(MANIFEST))
    return tmp_path / "refit"


def test_the_refit_costs_what_its_manifest_says(out: Path) -> None:
    cost = refit_cost(out, "scene_a", "lane0")
    assert (cost["wall_s"], cost["steps"], cost["refit_steps"], cost["enhance_s"]) == (100.0, 300, 300, 24.0)
    assert (cost["method"], cost["schedule"], cost["ply_sha256"]) == ("setdiff", "progressive", "f" * 64)


def test_a_snapshot_costs_its_share_of_the_refit(out: Path) -> None:
    assert snapshot_of(snapshot_folder(out, 100)) == (out, 100) and snapshot_of(out) is None
    cost = refit_cost(snapshot_folder(out, 100), "scene_a", "lane0")
    # 10 s set-up + 60 s x 100/300 of the steps + the first of 3 updates (30 s / 3); 24 s / 3 in the enhancer
    assert cost["wall_s"] == pytest.approx(40.0) and cost["enhance_s"] == pytest.approx(8.0)
    assert (cost["steps"], cost["refit_steps"], cost["ply_sha256"]) == (100, 100, "a" * 64)
    later = refit_cost(snapshot_folder(out, 200), "scene_a", "lane0")
    assert later["wall_s"] == pytest.approx(10.0 + 40.0 + 20.0) and later["ply_sha256"] == "b" * 64
    with pytest.raises(UsageError, match=r"no snapshot after 150 steps \(snapshots: \[100, 200\]\)"):
        refit_cost(snapshot_folder(out, 150), "scene_a", "lane0")
