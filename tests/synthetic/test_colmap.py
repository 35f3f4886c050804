"""The written COLMAP model, read back by pycolmap itself: cameras, poses, and sparse points that project
onto the rendered surfaces they were sampled from."""

from __future__ import annotations

import json

import numpy as np
import pycolmap

from setdiff_bench.io.images import read_rgb
from setdiff_bench.synthetic.generate import build_scene
from setdiff_bench.synthetic.rig import RIG, rig_camera
from tests.synthetic.synthetic_fixtures import SEED, small_preset


def test_pycolmap_reads_the_legacy_three_file_model(scene_dir):
    sparse = scene_dir / "sparse" / "0"
    assert not (sparse / "rigs.bin").exists() and not (sparse / "frames.bin").exists()
    rec = pycolmap.Reconstruction(str(sparse))
    meta = json.loads((scene_dir / "scene.json").read_text())
    assert sorted(img.name for img in rec.images.values()) == sorted(f["name"] for f in meta["frames"])
    assert len(rec.cameras) == 3
    for camera in rec.cameras.values():
        assert camera.model.name == "PINHOLE"
        assert (camera.width, camera.height) == (meta["width"], meta["height"])
        entry = meta["cameras"][0]
        assert np.allclose(camera.params, [entry["fx"], entry["fy"], entry["cx"], entry["cy"]])
    assert len(rec.points3D) == meta["num_points3d"] > 100


def test_colmap_poses_are_the_rig_poses(scene_dir):
    """World-to-camera poses in images.bin equal the generator's cameras (independent quaternion path)."""
    preset = small_preset()
    build = build_scene(preset, SEED, 0)
    rec = pycolmap.Reconstruction(str(scene_dir / "sparse" / "0"))
    by_name = {img.name: img for img in rec.images.values()}
    for traversal in build.traversals:
        for spec in RIG:
            for index in range(preset.timesteps):
                camera = rig_camera(traversal, index, spec, preset.width, preset.height)
                image = by_name[f"{traversal.name}_{spec.name}_{index:03d}.png"]
                assert np.allclose(image.cam_from_world().matrix(), camera.w2c[:3], atol=1e-9)
                assert rec.cameras[image.camera_id].model.name == "PINHOLE"


def test_points_project_onto_matching_colours_in_other_drives(scene_dir):
    """Sparse points were coloured from the lane0 training frames; projected by pycolmap into the lane1/lane2
    drives (other poses), visible points must land on pixels of the same colour."""
    rec = pycolmap.Reconstruction(str(scene_dir / "sparse" / "0"))
    xyz = np.stack([p.xyz for p in rec.points3D.values()])
    rgb = np.stack([p.color for p in rec.points3D.values()]).astype(np.float64) / 255.0
    match_rates, baseline_rates = [], []
    for image in rec.images.values():
        if not image.name.startswith(("lane1_front", "lane2_front")):
            continue
        camera = rec.cameras[image.camera_id]
        cam_points = (image.cam_from_world().matrix() @ np.c_[xyz, np.ones(len(xyz))].T).T
        in_front = cam_points[:, 2] > 0.5
        uv = camera.img_from_cam(cam_points[in_front])
        picture = read_rgb(scene_dir / "images" / image.name)
        h, w = picture.shape[:2]
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        cols, rows = np.floor(uv[inside]).astype(int).T
        colours = rgb[in_front][inside]
        difference = np.abs(picture[rows, cols] - colours).max(axis=1)
        match_rates.append(float((difference < 0.12).mean()))
        shuffled = np.random.default_rng(0).permutation(len(colours))
        baseline_rates.append(
            float((np.abs(picture[rows, cols] - colours[shuffled]).max(axis=1) < 0.12).mean())
        )
    assert match_rates
    assert np.mean(match_rates) > 0.6
    assert np.mean(match_rates) > np.mean(baseline_rates) + 0.25
