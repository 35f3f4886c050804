"""Novel-trajectory packets (issue 41): ``prepare --trajectory`` on a street scene of the synthetic layout.

References are hand-derived from the fixture's geometry: lane 0 drives along +x with cameras looking
along ``(1, 0, -0.05)`` and world up +z, so a camera's right axis is ``-y`` and ``shift:-s`` puts it
``s`` metres further along +y with the same rotation; all fit cameras are parallel, so Eq. 2 reduces to
``0.8 + 0.2 · (1 - distance / d_max)`` (the synthetic protocol's alpha and beta).
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from PIL import Image

from setdiff_bench.cameras import Camera
from setdiff_bench.cli.main import main
from setdiff_bench.errors import PacketError
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.packets.store import PacketStore, row_camera
from setdiff_bench.runtime.threads import torch_threads
from tests.packets.packet_fixtures import StreetScene, prepare_argv, tree_bytes
from tests.packets.trajectory.conftest import GROUPS, SHIFTS

METRES = {"shift-3m": 3.0, "shift-6m": 6.0}


def _pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), dtype=np.float64) / 255.0


def _moved(camera: Camera, offset: np.ndarray) -> Camera:
    """``camera`` with its centre moved by ``offset`` (world), rotation kept: ``t = -R (c + offset)``."""
    w2c = np.eye(4)
    w2c[:3, :3] = camera.R
    w2c[:3, 3] = -camera.R @ (camera.center + offset)
    return Camera(camera.K, w2c, camera.width, camera.height)


def test_targets_are_the_fit_frames_moved_and_have_no_ground_truth(
    street: tuple[Path, StreetScene], shifted_store: Path
) -> None:
    root, scene = street
    index = pd.read_parquet(shifted_store / "index.parquet")
    assert sorted(set(index["group"])) == sorted(GROUPS)
    assert set(index["split"]) == {"test"} and index["packet_id"].nunique() == 2
    targets = index[index["role"] == "target"]
    assert targets[["gt", "gt_sha256", "mask", "mask_sha256"]].isna().all().all()
    names = {p.name for p in (shifted_store / "packets").rglob("*.png")}
    assert not any(n.endswith(("_gt.png", "_mask.png")) for n in names)
    for row in index.to_dict("records"):  # every file that exists is hashed
        for column in ("image", "cmap"):
            digest = hashlib.sha256((shifted_store / row[column]).read_bytes()).hexdigest()
            assert digest == row[f"{column}_sha256"]
    fit = read_ply(root / "street_00" / "fits" / "lane0.ply")
    for group, metres in METRES.items():
        rows = targets[targets["group"] == group].sort_values("view").to_dict("records")
        assert [r["frame"] for r in rows] == [n.replace(".png", f"@{group}.png") for n in scene.train]
        for row, base_name in zip(rows, scene.train, strict=True):
            base = scene.cameras[base_name]
            expected = _moved(base, np.array([0.0, metres, 0.0]))
            camera = row_camera(row, world=True)
            np.testing.assert_allclose(camera.center, expected.center, atol=1e-9)
            np.testing.assert_allclose(camera.R, base.R, atol=1e-12)
            np.testing.assert_allclose(camera.K, base.K)
            with torch.no_grad():
                rgb = render(fit, [expected]).rgb[0].permute(1, 2, 0).double().numpy()
            assert np.abs(_pixels(shifted_store / row["image"]) - rgb.clip(0, 1)).max() <= 0.5 / 255 + 1e-6
            assert row["timestamp_us"] == int(base_name[-7:-4]) * 100_000  # the recorded frame's time


def test_references_are_recorded_fit_frames_chosen_by_eq2(
    street: tuple[Path, StreetScene], shifted_store: Path
) -> None:
    root, scene = street
    index = pd.read_parquet(shifted_store / "index.parquet")
    centres = np.stack([c.center for c in scene.cameras.values()])
    d_max = max(np.linalg.norm(a - b) for a in centres for b in centres)
    fit_centres = np.stack([scene.cameras[n].center for n in scene.train])
    for group, metres in METRES.items():
        moved = fit_centres + np.array([0.0, metres, 0.0])
        distance = np.linalg.norm(moved[:, None, :] - fit_centres[None, :, :], axis=-1)  # (target, candidate)
        score = (0.8 + 0.2 * (1.0 - distance / d_max)).mean(axis=0)
        order = sorted(range(len(scene.train)), key=lambda i: (-score[i], i))
        refs = index[(index["group"] == group) & (index["role"] == "ref")].sort_values("view")
        assert list(refs["frame"]) == [scene.train[i] for i in order]
        np.testing.assert_allclose(refs["overlap_score"], score[order], rtol=0, atol=1e-9)
        for row in refs.to_dict("records"):  # the clean capture, not a render
            capture = _pixels(root / "street_00" / "images" / row["frame"])
            assert np.array_equal(_pixels(shifted_store / row["image"]), capture)


def test_the_store_reads_targets_without_ground_truth(shifted_store: Path) -> None:
    store = PacketStore(shifted_store)
    packet_id = store.packet_ids()[0]
    packet = store.load_packet(packet_id)
    assert tuple(packet.targets.images.shape) == (4, 3, 32, 48)
    assert store.has_ground_truth(packet_id).tolist() == [False] * 4
    with pytest.raises(PacketError, match="has no ground truth"):
        store.load_ground_truth(packet_id)
    assert len(store.training_dataset("test", min_views=2, max_views=4)) == 0
    assert store.verify() == []


def test_rerun_skips_and_a_changed_file_is_rewritten(
    street: tuple[Path, StreetScene], shifted_store: Path, tmp_path: Path
) -> None:
    root, _ = street
    out = tmp_path / "store"
    shutil.copytree(shifted_store, out)
    before = tree_bytes(out)
    with torch_threads(1):
        again = prepare("synthetic", root, out, fits=root, progress=False, trajectories=SHIFTS)
    assert (again.planned, again.written, again.skipped, again.index_written) == (2, 0, 2, False)
    assert tree_bytes(out) == before
    row = pd.read_parquet(out / "index.parquet").query("role == 'target'").iloc[0]
    (out / row["image"]).write_bytes(b"not a png")
    problems = PacketStore(out).verify()
    assert problems == [f"{row['packet_id']}: {row['image']}: SHA-256 mismatch"]
    with torch_threads(1):
        redone = prepare("synthetic", root, out, fits=root, progress=False, trajectories=SHIFTS)
    assert (redone.written, redone.skipped) == (1, 1) and tree_bytes(out) == before
    fresh = tmp_path / "fresh"  # the same inputs give the same bytes
    with torch_threads(1):
        prepare("synthetic", root, fresh, fits=root, progress=False, trajectories=SHIFTS)
    assert tree_bytes(fresh) == before


def test_trajectory_packets_join_a_store_without_changing_its_packets(
    street: tuple[Path, StreetScene], tmp_path: Path
) -> None:
    root, _ = street
    plain, mixed = tmp_path / "plain", tmp_path / "mixed"
    with torch_threads(1):
        prepare("synthetic", root, plain, fits=root, progress=False)
        prepare("synthetic", root, mixed, fits=root, progress=False)
        prepare("synthetic", root, mixed, fits=root, progress=False, trajectories=SHIFTS[:1])
    plain_files, mixed_files = tree_bytes(plain), tree_bytes(mixed)
    packets = {k: v for k, v in mixed_files.items() if k.startswith("packets/")}
    assert {k: v for k, v in packets.items() if "shift-3m" not in k} == {
        k: v for k, v in plain_files.items() if k.startswith("packets/")
    }
    index = pd.read_parquet(mixed / "index.parquet")
    assert (
        index[index["group"] != "shift-3m"]
        .reset_index(drop=True)
        .equals(pd.read_parquet(plain / "index.parquet"))
    )
    assert (index["group"] == "shift-3m").sum() == 8


def test_a_pose_file_gives_targets_at_its_poses(street: tuple[Path, StreetScene], tmp_path: Path) -> None:
    root, scene = street
    base = scene.cameras[scene.train[0]]
    poses = []
    for i, offset in enumerate(([0.0, 1.0, 0.0], [2.0, 3.5, 0.0])):
        c2w = np.linalg.inv(_moved(base, np.array(offset)).w2c)
        poses.append({"name": f"p{i}.png", "c2w": c2w.tolist()})
    path = tmp_path / "poses.json"
    path.write_text(json.dumps({"poses": poses}))
    out = tmp_path / "store"
    with torch_threads(1):
        assert main([*prepare_argv(root, out), "--trajectory", str(path), "--no-progress"]) == 0
    targets = pd.read_parquet(out / "index.parquet").query("role == 'target'").sort_values("view")
    assert list(targets["group"].unique()) == ["poses-poses"] and list(targets["frame"]) == [
        "p0.png",
        "p1.png",
    ]
    for row, pose in zip(targets.to_dict("records"), poses, strict=True):
        np.testing.assert_allclose(row_camera(row, world=True).w2c, np.linalg.inv(pose["c2w"]), atol=1e-9)
    assert targets["timestamp_us"].isna().all()


def _refused(argv: list[str], out: Path, capsys: pytest.CaptureFixture[str]) -> str:
    with torch_threads(1):
        code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert not out.exists()
    return err[0]


@pytest.mark.parametrize(
    ("spec", "problem"),
    [
        ("shift:abc", "--trajectory: unknown trajectory 'shift:abc'"),
        ("lane:3", "--trajectory: unknown trajectory 'lane:3'"),
        ("shift:40", "--trajectory shift+40m (scene 'street_00'): 4 of 4 cameras leave the scene bounds"),
        ("shift:-40", "--trajectory shift-40m (scene 'street_00'): 4 of 4 cameras leave the scene bounds"),
    ],
)
def test_bad_trajectories_are_one_line_and_nothing_is_written(
    street: tuple[Path, StreetScene],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    spec: str,
    problem: str,
) -> None:
    root, _ = street
    out = tmp_path / "store"
    line = _refused([*prepare_argv(root, out), "--trajectory", spec, "--no-progress"], out, capsys)
    assert line.startswith(f"setdiff-bench prepare: error: {problem}"), line


def test_a_trajectory_given_twice_is_refused(
    street: tuple[Path, StreetScene], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root, _ = street
    out = tmp_path / "store"
    argv = [*prepare_argv(root, out), "--trajectory", "shift:3", "--trajectory", "shift:3.0"]
    line = _refused(argv, out, capsys)
    assert line == "setdiff-bench prepare: error: --trajectory: trajectory shift+3m given twice"


@pytest.mark.parametrize(
    ("c2w", "problem"),
    [
        (np.diag([2.0, 1.0, 1.0, 1.0]).tolist(), "rotation"),
        ([[float("nan")] * 4] * 4, "finite"),
    ],
)
def test_bad_pose_files_are_one_line_and_nothing_is_written(
    street: tuple[Path, StreetScene],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    c2w: list[list[float]],
    problem: str,
) -> None:
    root, _ = street
    path = tmp_path / "poses.json"
    path.write_text(json.dumps([{"name": "p", "c2w": c2w}]).replace("NaN", "NaN"))
    out = tmp_path / "store"
    line = _refused([*prepare_argv(root, out), "--trajectory", str(path)], out, capsys)
    assert str(path) in line and problem in line.lower(), line


def test_a_yaw_turns_each_fit_camera_in_place(street: tuple[Path, StreetScene], tmp_path: Path) -> None:
    root, scene = street
    out = tmp_path / "store"
    with torch_threads(1):
        prepare("synthetic", root, out, fits=root, progress=False, trajectories=["yaw:10"])
    targets = pd.read_parquet(out / "index.parquet").query("role == 'target'").sort_values("view")
    assert set(targets["group"]) == {"yaw+10deg"}
    for row, base_name in zip(targets.to_dict("records"), scene.train, strict=True):
        base, camera = scene.cameras[base_name], row_camera(row, world=True)
        np.testing.assert_allclose(camera.center, base.center, atol=1e-9)
        cos = float(camera.view_direction @ base.view_direction)
        assert cos == pytest.approx(np.cos(np.radians(10.0)), abs=1e-12)
        # turned right: the new optical axis leans toward the old right axis (R[0])
        assert float(camera.view_direction @ base.R[0]) == pytest.approx(np.sin(np.radians(10.0)), abs=1e-12)


def test_names_of_trajectory_frames_and_groups() -> None:
    from setdiff_bench.packets.plan_trajectories import trajectory_frame_name, trajectory_group_name

    assert trajectory_frame_name("lane0_front_000.png", "shift+3m") == "lane0_front_000@shift+3m.png"
    assert trajectory_frame_name("CAM_FRONT/a.b.jpg", "yaw-5deg") == "CAM_FRONT/a.b@yaw-5deg.jpg"
    assert trajectory_frame_name("frame", "shift+3m") == "frame@shift+3m"
    assert trajectory_group_name("shift+3m", "lane0", ["lane0", "lane0"]) == "shift+3m"
    assert trajectory_group_name("shift+3m", "n3", ["holdout8", "n3"]) == "shift+3m@n3"
