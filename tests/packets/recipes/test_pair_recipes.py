"""``prepare --pairs``: training packets from a single-trajectory capture (issue 41).

The capture is one street scene of the synthetic layout (``tests.packets.packet_fixtures``): the synthetic
protocol's recorded frames are lane 0's front camera minus the held-out timestep 2, i.e.
``lane0_front_000, 001, 003, 004``; the multi-camera protocol below records lane 0's three cameras at all
five timesteps.  Fits are tiny (20 iterations), so each test takes seconds.  Which frames the degraded fit
sees is read from the fitting call itself (``load_fit_views`` wrapped); targets and references from the
index; every expectation is written out by hand.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.runtime.threads import torch_threads
from tests.packets.recipes.pairs_common import ITERATIONS, RECORDED, F, packets_of, prepare_pairs, spy_fits

#: A protocol whose recorded frames are lane 0's three cameras (the synthetic protocol's settings otherwise).
MULTI_CAMERA = """
format = "setdiff-protocol/1"
name = "lane0_cameras"
dataset = "synthetic"
description = "lane 0, all three cameras"
[loader]
masks = "require_test"
[split]
rule = "interleaved"
test_fraction = [2, 5]
[images]
resolution = "native"
resize = "crop"
masks = "dataset"
[references]
alpha = 0.8
beta = 0.2
aggregate = "mean"
train = 6
test = 8
[packets]
train_views = 12
test_views = 16
train_min_views = 8
train_max_views = 12
[render]
cmap_clip = 3.0
[[groups]]
name = "lane+1"
rule = "select"
fit_key = "lane0"
fit = { lane_offset = 0 }
targets = { lane_offset = 1, sensor = "front" }
"""


@pytest.fixture
def fit_calls(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """Each degraded fit's frame names, iterations and ``stop_after`` (the real fit still runs)."""
    return spy_fits(monkeypatch)


def test_sparse_fits_every_second_frame_and_targets_the_frames_between(
    capture: Path, tmp_path: Path, fit_calls: list[dict[str, Any]]
) -> None:
    out = tmp_path / "store"
    summary = prepare_pairs(capture, out, "sparse:2")
    # recorded 000, 001, 003, 004: positions 0 and 2 are fitted, 1 and 3 are the targets
    assert fit_calls == [
        {
            "frames": [F.format(0), F.format(3)],
            "iterations": ITERATIONS,
            "stop_after": None,
            "ply": "lane0@sparse2.ply",
        }
    ]
    # two references at most (the fit saw two frames): both; 2 targets fit in one train packet of 12 views
    assert packets_of(out) == {
        "synthetic__street-00__sparse2__0000": ([F.format(1), F.format(4)], {F.format(0), F.format(3)})
    }
    index = pd.read_parquet(out / "index.parquet")
    assert set(index["group"]) == {"sparse2"} and set(index["split"]) == {"train"}
    assert set(index["fit_key"]) == {"lane0@sparse2"}
    targets = index[index["role"] == "target"]
    assert targets["gt"].notna().all() and targets["mask"].notna().all()  # recorded frames: ground truth
    # the ground truth is the capture itself (the fixture's 48x32 images are the working size)
    for frame, gt in zip(targets["frame"], targets["gt"], strict=True):
        written = (out / gt).read_bytes()
        assert hashlib.sha256(written).hexdigest() == targets[targets["frame"] == frame]["gt_sha256"].iloc[0]
    assert (
        summary.written == 1
        and len(PacketStore(out).training_dataset("train", min_views=2, max_views=4)) == 1
    )
    # a rerun skips everything, writes nothing and fits nothing
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    again = prepare_pairs(capture, out, "sparse:2")
    assert (again.written, again.skipped, again.fits_trained) == (0, 1, 0)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_underfit_stops_the_fit_and_never_uses_a_target_as_its_reference(
    capture: Path, tmp_path: Path, fit_calls: list[dict[str, Any]]
) -> None:
    out = tmp_path / "store"
    prepare_pairs(capture, out, "underfit:0.25")
    # every recorded frame is fitted; the full run's schedule (20 iterations) stopped after round(0.25 x 20) = 5
    assert fit_calls == [
        {"frames": RECORDED, "iterations": ITERATIONS, "stop_after": 5, "ply": "lane0@underfit25.ply"}
    ]
    # 4 fit frames: 3 references (one less than the frames), so 4 - 3 = 1 target per packet
    assert packets_of(out) == {
        f"synthetic__street-00__underfit25__{i:04d}": ([frame], set(RECORDED) - {frame})
        for i, frame in enumerate(RECORDED)
    }


def test_cross_camera_fits_one_camera_and_targets_the_others(
    capture: Path, tmp_path: Path, fit_calls: list[dict[str, Any]]
) -> None:
    protocol = tmp_path / "lane0_cameras.toml"
    protocol.write_text(MULTI_CAMERA)
    front = [F.format(i) for i in range(5)]
    left = [f"lane0_front_left_{i:03d}.png" for i in range(5)]
    right = [f"lane0_front_right_{i:03d}.png" for i in range(5)]
    out = tmp_path / "store"
    prepare_pairs(capture, out, "cross-camera", protocol=str(protocol))
    # 5 frames per camera: the tie goes to the first name, front
    assert fit_calls[0]["frames"] == front and fit_calls[0]["ply"] == "lane0@cross-camera-front.ply"
    # 5 references (the protocol's 6, capped by the 5 front frames); 12 - 5 = 7 targets per packet at most:
    # the 10 side-camera frames in recorded order, cut 5 + 5
    assert packets_of(out) == {
        "lane0-cameras__street-00__cross-camera__0000": (left, set(front)),
        "lane0-cameras__street-00__cross-camera__0001": (right, set(front)),
    }
    named = tmp_path / "named"
    prepare_pairs(capture, named, "cross-camera:front_right", protocol=str(protocol))
    assert fit_calls[1]["frames"] == right
    packets = packets_of(named)
    assert sorted(t for targets, _ in packets.values() for t in targets) == sorted(front + left)
    assert all(refs == set(right) for _, refs in packets.values())


def test_recipe_packets_beside_protocol_packets_leave_them_byte_identical(
    capture: Path, tmp_path: Path
) -> None:
    out = tmp_path / "store"
    with torch_threads(1):
        prepare("synthetic", capture, out, fits=capture, progress=False)
    protocol_rows = pd.read_parquet(out / "index.parquet")
    files = {p: p.read_bytes() for p in (out / "packets").rglob("*") if p.is_file()}
    prepare_pairs(capture, out, "sparse:3")
    index = pd.read_parquet(out / "index.parquet")
    assert index[index["group"] != "sparse3"].reset_index(drop=True).equals(protocol_rows)
    assert all(path.read_bytes() == data for path, data in files.items())
    # sparse:3 of 000, 001, 003, 004: positions 0 and 3 fitted (000, 004); targets 001, 003
    assert packets_of(out)["synthetic__street-00__sparse3__0000"] == (
        [F.format(1), F.format(3)],
        {F.format(0), F.format(4)},
    )


@pytest.mark.parametrize(
    ("pairs", "message"),
    [
        ("blur", "--pairs: unknown recipe 'blur'; recipes: sparse, underfit, cross-camera, cycle"),
        ("sparse:1", "--pairs: sparse:1: the frame step must be an integer >= 2"),
        ("sparse:x", "--pairs: sparse:x: the frame step must be an integer >= 2"),
        (
            "underfit:0.9",
            "--pairs: underfit:0.9: the share of the fit's iterations must be a number from 0.25 to 0.75",
        ),
        (
            "underfit:nan",
            "--pairs: underfit:nan: the share of the fit's iterations must be a number from 0.25 to 0.75",
        ),
        ("sparse,sparse:4", "--pairs: recipe sparse4 given twice"),
        (
            "cycle:0.5",
            "--pairs: cycle:0.5: the sideways shift must be a number of metres from 1 to 6 (negative: to the left)",
        ),
        ("cycle:-7", "--pairs: cycle:-7: the sideways shift must be a number of metres from 1 to 6"),
        ("cycle:inf", "--pairs: cycle:inf: the sideways shift must be a number of metres from 1 to 6"),
        ("cycle:2m", "--pairs: cycle:2m: the sideways shift must be a number of metres from 1 to 6"),
        ("cycle,cycle:2.0", "--pairs: recipe cycle2m given twice"),
        ("sparse,cycle:-3,cycle:-3", "--pairs: recipe cycle-3m given twice"),
        (
            "cross-camera",
            "--pairs: recipe cross-camera needs recorded frames of several cameras; scene 'street_00' (fit 'lane0') has one (front)",
        ),
        ("sparse,cross-camera:rear", "--pairs: recipe cross-camera needs recorded frames of several cameras"),
    ],
)
def test_bad_recipes_are_one_line_exit_2_and_nothing_written(
    capture: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], pairs: str, message: str
) -> None:
    out = tmp_path / "never"
    argv = [
        "prepare",
        "synthetic",
        "--root",
        str(capture),
        "--fit",
        "--fit-iterations",
        "5",
        "--out",
        str(out),
    ]
    with torch_threads(1):
        code = main([*argv, "--pairs", pairs, "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not out.exists()
    assert err[0].startswith(f"setdiff-bench prepare: error: {message}")


def test_a_camera_the_capture_lacks_is_named(
    capture: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    protocol = tmp_path / "lane0_cameras.toml"
    protocol.write_text(MULTI_CAMERA)
    out = tmp_path / "never"
    argv = [
        "prepare",
        "synthetic",
        "--root",
        str(capture),
        "--protocol",
        str(protocol),
        "--fit",
        "--out",
        str(out),
    ]
    code = main([*argv, "--pairs", "cross-camera:rear"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not out.exists()
    assert err[0] == (
        "setdiff-bench prepare: error: --pairs: recipe cross-camera-rear: scene 'street_00' (fit 'lane0') has no "
        "camera 'rear'; cameras: front, front_left, front_right"
    )
    code = main([*argv, "--pairs", "sparse", "--trajectory", "shift:-3"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err == [
        "setdiff-bench prepare: error: --pairs: give --pairs or --trajectory, not both (run prepare once for each)"
    ]
    assert not out.exists()
