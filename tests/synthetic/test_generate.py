"""Generated scenes: EUVS layout, scene.json, split files, masks, determinism, and the loaders reading them."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.gaussians.render import render
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.images import read_image_raw, read_rgb
from setdiff_bench.loaders import load_scenes
from setdiff_bench.synthetic.generate import build_scene, generate_scene
from setdiff_bench.synthetic.rig import RIG, rig_camera
from tests.synthetic.synthetic_fixtures import SEED, small_preset


def file_hashes(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): sha256_file(p) for p in sorted(folder.rglob("*")) if p.is_file()}


def test_same_seed_gives_byte_identical_files(scene_dir, tmp_path):
    again = generate_scene(tmp_path, small_preset(), SEED, 0)
    first, second = file_hashes(scene_dir), file_hashes(again)
    assert list(first) == list(second)
    assert first == second
    assert len(first) == 2 * 36 + 3 + 3  # images + masks, 3 COLMAP files, scene.json + 2 set files


def test_layout_on_disk(scene_dir):
    preset = small_preset()
    names = sorted(p.name for p in (scene_dir / "images").iterdir())
    assert len(names) == 4 * 3 * preset.timesteps
    assert (
        sorted(p.name for p in (scene_dir / "dynamic_masks").iterdir()) == names
    )  # stems are names' stems (.png)
    assert sorted(p.name for p in (scene_dir / "sparse" / "0").iterdir()) == [
        "cameras.bin",
        "images.bin",
        "points3D.bin",
    ]
    assert not list(scene_dir.parent.glob(".*"))  # no staging folder left behind
    train = (scene_dir / "train_set.txt").read_text().split()
    test = (scene_dir / "test_set.txt").read_text().split()
    # fit frames: lane0 front minus the held-out timestep 1 (holdout_every 3 → index % 3 == 1)
    assert train == ["lane0_front_000.png", "lane0_front_002.png"]
    assert test == sorted(set(names) - set(train))
    image = read_rgb(scene_dir / "images" / names[0])
    assert image.shape == (preset.height, preset.width, 3)
    assert image.std() > 0.05  # a textured street, not a flat colour


def test_scene_json(scene_dir):
    meta = json.loads((scene_dir / "scene.json").read_text())
    preset = small_preset()
    assert meta["format"] == "setdiff-synthetic/1"
    assert meta["scene"] == scene_dir.name == f"scene_{SEED:04d}_00"
    assert (meta["width"], meta["height"]) == (preset.width, preset.height)
    assert meta["lane_width_m"] == 3.5 and meta["num_lanes"] >= 3
    assert [(t["name"], t["kind"], t["lane_offset"]) for t in meta["traversals"]] == [
        ("lane0", "straight", 0),
        ("lane1", "straight", 1),
        ("lane2", "straight", 2),
        ("turn", "lane_change", None),
    ]
    assert [(c["name"], c["yaw_deg"]) for c in meta["cameras"]] == [
        ("front", 0.0),
        ("front_left", 45.0),
        ("front_right", -45.0),
    ]
    train = set((scene_dir / "train_set.txt").read_text().split())
    for frame in meta["frames"]:
        assert frame["name"] == f"{frame['traversal']}_{frame['camera']}_{frame['index']:03d}.png"
        assert frame["timestamp_us"] == 100_000 * frame["index"]  # 10 Hz
        assert frame["split"] == ("train" if frame["name"] in train else "test")
        mask = read_image_raw(scene_dir / "dynamic_masks" / frame["name"], "uint8")
        assert mask.shape == (preset.height, preset.width, 1)
        assert set(np.unique(mask)) <= {0, 255}
        assert frame["has_dynamic"] == bool((mask == 0).any())
    assert meta["dynamic_objects"] == 4
    assert any(f["has_dynamic"] for f in meta["frames"])


def test_loaders_read_the_scene(scene_dir):
    [scene] = load_scenes("synthetic", scene_dir)
    assert scene.name == scene_dir.name and len(scene.frames) == 36
    assert scene.points3d is not None and len(scene.points3d) > 100
    lane1 = [f for f in scene.frames if f.traversal == "lane1"]
    assert {f.metadata["lane_offset"] for f in lane1} == {1}
    [euvs] = load_scenes("euvs", scene_dir)  # the plain EUVS reader reads it unchanged
    assert sorted(euvs.frame_names) == sorted(scene.frame_names)


def test_different_seeds_give_different_scenes(scene_dir):
    preset = small_preset()
    a = read_rgb(scene_dir / "images" / "lane0_front_000.png")
    other = build_scene(preset, SEED + 1, 0)
    camera = rig_camera(other.traversals[0], 0, RIG[0], preset.width, preset.height)
    with torch.no_grad():
        b = render(other.world.static, [camera]).rgb[0].permute(1, 2, 0).numpy()
    assert np.abs(a - b).mean() > 0.03
    assert build_scene(preset, SEED + 1, 0).world.layout == other.world.layout  # and reproducible
