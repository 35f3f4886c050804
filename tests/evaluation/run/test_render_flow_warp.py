"""Warp error of targets without ground truth, with the flow of their 3DGS renders (issue 41).

A small nuScenes-like store: one camera's targets with ground truth in two time groups (one sequence across
them, flow from the ground truth), and two trajectory groups without ground truth (``shift+3m``,
``shift+6m``) on the same camera and timestamps, whose "renders" are the textured plane seen from cameras
moved sideways, blurred and noised.  Images are 32×48 and flow is DIS, so the module runs in seconds.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import torch

from setdiff_bench.errors import PacketError
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.io.run_layout import MANIFEST_FILE, METRICS_FILE, SEQUENCES_FILE
from setdiff_bench.metrics.warp import warp_error, warp_reference
from setdiff_bench.packets.index import merge_index, packet_id
from setdiff_bench.packets.writer import PacketHeader, ViewContent, write_packet
from setdiff_bench.protocols import Block
from setdiff_bench.reporting.leaderboard.cells import measured_row
from setdiff_bench.reporting.leaderboard.columns import ALL
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store, camera_at, degrade, plane_view

SHIFTS = {"shift+3m": 0.3, "shift+6m": 0.6}
FRAMES = 4
GT_SPEC = StoreSpec(
    dataset="nuscenes",
    protocol="nuscenes",
    groups=("10-11s", "11-12s"),
    scenes=("scene-0001",),
    sensors=("CAM_FRONT",),
    targets=3,
    timestamps=True,
)


def add_trajectories(
    root: Path,
    *,
    protocol: str = "nuscenes",
    dataset: str = "nuscenes",
    shifts: dict[str, float] = SHIFTS,
    timestamps: bool = True,
) -> Path:
    """Write one packet per trajectory group: ``FRAMES`` time-stamped targets without ground truth."""
    for g, (group, shift) in enumerate(shifts.items()):
        camera = camera_at(-0.5)
        image, points, alpha = plane_view(camera, 2.5)
        reference = ViewContent(
            frame="CAM_FRONT/ref.jpg",
            sensor="CAM_FRONT",
            traversal="lane0",
            timestamp_us=None,
            camera=camera,
            camera_world=camera,
            image=image,
            cmap=points,
            alpha=alpha,
            overlap_score=0.9,
        )
        targets = []
        for j in range(FRAMES):
            camera = camera_at(shift + 0.08 * j)
            render, points, alpha = plane_view(camera, 2.5)
            targets.append(
                ViewContent(
                    frame=f"CAM_FRONT/{j:06d}@{group}.jpg",
                    sensor="CAM_FRONT",
                    traversal="lane0",
                    timestamp_us=10_000_000 + 100_000 * j if timestamps else None,
                    camera=camera,
                    camera_world=camera,
                    image=degrade(render, seed=100 * g + j),
                    cmap=points,
                    alpha=alpha,
                )
            )
        header = PacketHeader(
            packet_id=packet_id(protocol, "scene-0001", group, 0),
            dataset=dataset,
            protocol=protocol,
            group=group,
            split="test",
            scene="scene-0001",
            fit_key="lane0",
            scale=1.0,
            recipe=f"trajectory-{group}",
        )
        write_packet(root, header, [reference], targets)
    merge_index(root)
    return root


def read_float(path: Path) -> torch.Tensor:
    """``(3, H, W)`` float32 in [0, 1] of an 8-bit PNG, read with OpenCV (not the project's reader)."""
    pixels = cv2.cvtColor(cv2.imread(str(path), cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    return torch.from_numpy(pixels.astype(np.float32) / 255.0).permute(2, 0, 1)


def settings(
    method: str = "identity", cache: Path | None = None, warp: str = "auto", **options: object
) -> RunSettings:
    """PSNR only (no LPIPS weights needed), DIS flow, no flow cache unless ``cache``."""
    return RunSettings(
        method,
        options,
        split=None,
        metrics=("psnr",),
        warp=warp,  # type: ignore[arg-type]
        flow_method="dis",
        warp_cache=None if cache is None else str(cache),
    )


@pytest.fixture(scope="module")
def stores(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """``gt``: the ground-truth packets alone; ``mixed``: the same plus the two trajectory groups."""
    base = tmp_path_factory.mktemp("render_flow")
    with torch_threads(1):
        gt = build_store(base / "gt", GT_SPEC)
        mixed = build_store(base / "mixed", GT_SPEC)
        add_trajectories(mixed)
    return {"gt": gt, "mixed": mixed, "base": base}


@pytest.fixture(scope="module")
def identity(stores: dict[str, Path]) -> Path:
    out = stores["base"] / "identity"
    with torch_threads(1):
        run_method(stores["mixed"], out, settings(), progress=False)
    return out


def render_sequence(store: Path, group: str) -> torch.Tensor:
    """``(T, 3, H, W)`` the group's target renders, read from the packet files in timestamp order."""
    index = pd.read_parquet(store / "index.parquet")
    rows = index[(index["role"] == "target") & (index["group"] == group)].sort_values("timestamp_us")
    return torch.stack([read_float(store / path) for path in rows["image"]])


def test_enhanced_equal_to_the_renders_score_the_renders_own_warp_error(
    stores: dict[str, Path], identity: Path
) -> None:
    sequences = pd.read_parquet(identity / SEQUENCES_FILE)
    render = sequences[sequences["flow_source"] == "render"].set_index("group")
    for group in SHIFTS:
        renders = render_sequence(stores["mixed"], group)
        expected = warp_error(renders, warp_reference(renders, method="dis"))
        assert render.loc[group, "warp"] == pytest.approx(float(expected), rel=1e-6, abs=1e-9)
        assert render.loc[group, "warp"] > 0.1  # the renders' noise is not consistent from frame to frame
    # the line and the manifest no longer name warp as skipped; the image metrics still are
    manifest = json.loads((identity / MANIFEST_FILE).read_text())
    assert manifest["skipped"]["metrics"] == ["psnr"] and manifest["skipped"]["targets"] == 2 * FRAMES


def test_flow_comes_from_the_renders_not_from_the_enhanced_frames(
    stores: dict[str, Path], identity: Path, tmp_path: Path
) -> None:
    """A flickering output is scored with the renders' flow; a constant output has warp error 0."""
    flicker, flat = tmp_path / "flicker", tmp_path / "flat"
    shutil.copytree(identity / "images", flicker)
    shutil.copytree(identity / "images", flat)
    metrics = pd.read_parquet(identity / METRICS_FILE)
    for row in metrics.itertuples():
        relative = Path(row.image).relative_to("images")
        pixels = cv2.imread(str(identity / row.image)).astype(np.int64)
        offset = 12 if int(row.timestamp_us) // 100_000 % 2 else -12
        cv2.imwrite(str(flicker / relative), np.clip(pixels + offset, 0, 255).astype(np.uint8))
        cv2.imwrite(str(flat / relative), np.full_like(pixels, 128).astype(np.uint8))
    with torch_threads(1):
        run_method(
            stores["mixed"], tmp_path / "a", settings("precomputed", source=str(flicker)), progress=False
        )
        run_method(stores["mixed"], tmp_path / "b", settings("precomputed", source=str(flat)), progress=False)
    scored = pd.read_parquet(tmp_path / "a" / SEQUENCES_FILE)
    scored = scored[scored["flow_source"] == "render"].set_index("group")
    for group in SHIFTS:
        renders = render_sequence(stores["mixed"], group)
        rows = metrics[metrics["group"] == group].sort_values("timestamp_us")
        frames = torch.stack([read_float(flicker / Path(p).relative_to("images")) for p in rows["image"]])
        expected = warp_error(frames, warp_reference(renders, method="dis"))
        assert scored.loc[group, "warp"] == pytest.approx(float(expected), rel=1e-6, abs=1e-9)
    # bilinear sampling of a constant image is that constant up to float32 rounding (0-255 units)
    assert pd.read_parquet(tmp_path / "b" / SEQUENCES_FILE)["warp"].tolist() == pytest.approx(
        [0.0] * 3, abs=1e-6
    )


def test_trajectory_groups_are_never_one_sequence(identity: Path) -> None:
    sequences = pd.read_parquet(identity / SEQUENCES_FILE)
    render = sequences[sequences["flow_source"] == "render"]
    assert list(render["group"]) == list(SHIFTS) and list(render["frames"]) == [FRAMES, FRAMES]
    assert list(render["first_frame"]) == [f"CAM_FRONT/000000@{g}.jpg" for g in SHIFTS]
    assert list(render["last_frame"]) == [f"CAM_FRONT/{FRAMES - 1:06d}@{g}.jpg" for g in SHIFTS]
    assert set(render["sensor"]) == {"CAM_FRONT"} and set(render["protocol"]) == {"nuscenes"}


def test_ground_truth_sequences_are_unchanged(
    stores: dict[str, Path], identity: Path, tmp_path: Path
) -> None:
    """The GT sequence of the mixed store equals that of the store without trajectories, its flow cache
    entry is shared (same key as before), and the render flows are cached under keys of their own."""
    cache = tmp_path / "flows"
    with torch_threads(1):
        run_method(stores["gt"], tmp_path / "gt", settings(cache=cache), progress=False)
        first = {p.name: p.stat().st_mtime_ns for p in cache.glob("*.safetensors")}
        run_method(stores["mixed"], tmp_path / "mixed", settings(cache=cache), progress=False)
    after = {p.name: p.stat().st_mtime_ns for p in cache.glob("*.safetensors")}
    assert len(first) == 1 and len(after) == 3 and all(after[name] == first[name] for name in first)
    alone = pd.read_parquet(tmp_path / "gt" / SEQUENCES_FILE)
    mixed = pd.read_parquet(identity / SEQUENCES_FILE)
    assert list(mixed["flow_source"]) == ["ground_truth", "render", "render"]
    assert list(alone["flow_source"]) == ["ground_truth"] and alone["group"].isna().all()
    assert alone.drop(columns="group").iloc[0].to_dict() == mixed.drop(columns="group").iloc[0].to_dict()
    assert pd.isna(mixed["group"].iloc[0])
    assert alone["frames"].tolist() == [2 * GT_SPEC.targets]  # across the two time groups, as before
    with_cache = pd.read_parquet(tmp_path / "mixed" / SEQUENCES_FILE)
    assert with_cache["warp"].tolist() == mixed["warp"].tolist()


def test_auto_follows_the_protocol_and_on_works_on_other_protocols(tmp_path: Path) -> None:
    with torch_threads(1):
        store = add_trajectories(tmp_path / "store", protocol="synthetic", dataset="synthetic")
        auto = run_method(store, tmp_path / "auto", settings(), progress=False)
        run_method(store, tmp_path / "on", settings(warp="on"), progress=False)
    assert auto.skipped_metrics is not None and auto.skipped_metrics.metrics == ("psnr",)
    assert not (tmp_path / "auto" / SEQUENCES_FILE).exists()
    sequences = pd.read_parquet(tmp_path / "on" / SEQUENCES_FILE)
    assert list(sequences["group"]) == list(SHIFTS) and set(sequences["flow_source"]) == {"render"}


def test_warp_on_refuses_a_trajectory_without_timestamps(tmp_path: Path) -> None:
    with torch_threads(1):
        store = add_trajectories(tmp_path / "store", shifts={"poses-path": 0.3}, timestamps=False)
        auto = run_method(store, tmp_path / "auto", settings(), progress=False)
        assert len(pd.read_parquet(auto.out / SEQUENCES_FILE)) == 0
        with pytest.raises(PacketError, match="group 'poses-path' has targets without one"):
            run_method(store, tmp_path / "on", settings(warp="on"), progress=False)


def test_leaderboard_cells_keep_render_sequences_out_of_the_pooled_block(identity: Path) -> None:
    """The pooled block's warp is the mean over ground-truth sequences only; a trajectory block gets the mean
    over its own render sequences."""
    metrics = pd.read_parquet(identity / METRICS_FILE)
    images = metrics[metrics["psnr"].notna()]  # what build_leaderboard passes: groups with ground truth
    sequences = pd.read_parquet(identity / SEQUENCES_FILE)
    blocks = [Block(ALL, "All"), Block("shift+3m", "shift+3m")]
    row = measured_row("identity", images, sequences, blocks, ["psnr"], ["warp"], group_sequences=True)
    truth = sequences[sequences["flow_source"] == "ground_truth"]["warp"]
    shift = sequences[sequences["group"] == "shift+3m"]["warp"]
    assert row.values[(ALL, "warp")] == float(truth.mean()) and row.counts[(ALL, "warp")] == 1
    assert row.values[("shift+3m", "warp")] == float(shift.mean()) and row.counts[("shift+3m", "warp")] == 1
    # a sequences.parquet written before flow_source existed pools every row, as it always did
    legacy = sequences[sequences["flow_source"] == "ground_truth"].drop(columns=["flow_source", "group"])
    old = measured_row("identity", images, legacy, blocks, ["psnr"], ["warp"], group_sequences=True)
    assert old.values[(ALL, "warp")] == float(truth.mean()) and ("shift+3m", "warp") not in old.values
    # without group_sequences (today's build_leaderboard) no group block gets a warp cell
    plain = measured_row("identity", images, sequences, blocks, ["psnr"], ["warp"])
    assert plain.values[(ALL, "warp")] == float(truth.mean()) and ("shift+3m", "warp") not in plain.values


def test_leaderboard_shows_each_trajectory_blocks_render_warp(
    identity: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``leaderboard`` end to end: a trajectory block gets a Warp column holding its own render sequences'
    mean (1 decimal, the metric's display), the pooled block the ground-truth sequences' mean, and the caption
    says where a trajectory block's flow came from."""
    from setdiff_bench.cli.main import main

    runs = tmp_path / "runs"
    shutil.copytree(identity, runs / "identity")
    dataset = str(pd.read_parquet(identity / METRICS_FILE)["dataset"].iloc[0])
    out = tmp_path / "board"
    argv = ["leaderboard", "--dataset", dataset, "--runs", str(runs), "--split", "all", "--format", "md"]
    argv += ["--metrics", "psnr"]
    assert main([*argv, "--out", str(out)]) == 0
    capsys.readouterr()
    text = "\n".join(p.read_text() for p in sorted(out.glob("*.md")))
    sequences = pd.read_parquet(identity / SEQUENCES_FILE)
    for group in ("shift+3m", "shift+6m"):
        expected = sequences[sequences["group"] == group]["warp"].mean()
        assert f"{expected:.1f}" in text, (group, expected, text)
    assert "flow and occlusion from the 3DGS renders" in text
