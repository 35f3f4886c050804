"""Sparse-view scenes: DL3DV's on-disk layout read by loaders/dl3dv.py, determinism from (seed, i), the
3DGS-Enhancer views of the fits, the sparse protocol config, and the reference ceiling on a tiny scene."""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.images import read_rgb
from setdiff_bench.loaders import load_scenes
from setdiff_bench.protocols import load_protocol
from setdiff_bench.protocols.rules import sparse_view_indices
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.synthetic.sparse import (
    FULL_SCALE,
    build_sparse_scene,
    fit_sparse_scene,
    fit_views,
    generate_sparse_scene,
    get_sparse_preset,
    sparse_scene_name,
    static_world,
)

REPO = Path(__file__).resolve().parents[2]
SPARSE_PROTOCOL = "dl3dv_sparse_synthetic"  # the packaged protocol


def tiny_preset():
    """The ``sparse_tiny`` preset with fewer frames and fit iterations (seconds)."""
    preset = get_sparse_preset("sparse_tiny")
    return replace(preset, frames=20, fit=preset.fit.rescaled(10))


@pytest.fixture(scope="module")
def sparse_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("sparse")
    with torch_threads(1):
        generate_sparse_scene(root, tiny_preset(), 3, 1)
    return root


def file_hashes(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): sha256_file(p) for p in sorted(folder.rglob("*")) if p.is_file()}


def test_dl3dv_layout_on_disk(sparse_root):
    preset = tiny_preset()
    scene = sparse_root / sparse_scene_name(3, 1)
    assert scene.name == "sparse_0003_01"
    names = sorted(p.name for p in (scene / "images_4").iterdir())
    assert names == [f"frame_{i:05d}.png" for i in range(1, preset.frames + 1)]
    assert sorted(p.name for p in (scene / "colmap" / "sparse" / "0").iterdir()) == [
        "cameras.bin",
        "images.bin",
        "points3D.bin",
    ]
    assert not list(sparse_root.glob(".*"))  # no staging folder left behind
    image = read_rgb(scene / "images_4" / names[0])
    assert image.shape == (preset.height, preset.width, 3)
    assert image.std() > 0.05
    meta = json.loads((scene / "scene.json").read_text())
    assert meta["format"] == "setdiff-synthetic-sparse/1"
    assert (meta["seed"], meta["index"], meta["preset"]) == (3, 1, "sparse_tiny")
    assert meta["full_resolution"] == [preset.width * FULL_SCALE, preset.height * FULL_SCALE]
    assert meta["fit_views"] == fit_views(preset)


def test_dl3dv_loader_reads_the_scene(sparse_root):
    import pycolmap

    preset = tiny_preset()
    build = build_sparse_scene(preset, 3, 1)
    scenes = load_scenes("dl3dv", sparse_root, distortion="ignore")
    assert [s.name for s in scenes] == ["sparse_0003_01"]
    scene = scenes[0]
    assert [f.name for f in scene.frames] == [f"frame_{i:05d}.png" for i in range(1, preset.frames + 1)]
    assert scene.metadata["poses"] == "colmap"
    assert scene.points3d is not None and len(scene.points3d) > 100
    for frame, camera in zip(scene.frames, build.cameras, strict=True):
        # the COLMAP camera is the full resolution (4x); the loader rescales it to images_4 exactly
        assert (frame.camera.width, frame.camera.height) == (preset.width, preset.height)
        np.testing.assert_allclose(frame.camera.K, camera.K, atol=1e-9)
        np.testing.assert_allclose(frame.camera.w2c, camera.w2c, atol=1e-6)
    model = pycolmap.Reconstruction(str(sparse_root / "sparse_0003_01" / "colmap" / "sparse" / "0"))
    (cam,) = model.cameras.values()
    assert cam.model.name == "OPENCV" and list(cam.params[4:]) == [0.0, 0.0, 0.0, 0.0]
    assert (cam.width, cam.height) == (preset.width * FULL_SCALE, preset.height * FULL_SCALE)


def test_sparse_protocol_applies_dl3dv_rules(sparse_root):
    protocol = load_protocol(SPARSE_PROTOCOL)
    assert protocol.dataset == "dl3dv" and protocol.images.resolution is None  # native
    dl3dv = load_protocol("dl3dv")
    assert [(g.name, g.fit_key, dict(g.params)) for g in protocol.groups] == [
        (g.name, g.fit_key, dict(g.params)) for g in dl3dv.groups
    ]
    scene = load_scenes("dl3dv", sparse_root, distortion="ignore")[0]
    names = [f.name for f in scene.frames]
    for group in protocol.groups:
        chosen = group.select(scene)
        indices = sparse_view_indices(len(names), int(group.params["views"]), group.params["gaps"])
        assert (
            [f.name for f in chosen.fit]
            == [names[i] for i in indices]
            == fit_views(tiny_preset())[group.fit_key]
        )
        assert len(chosen.targets) == indices[-1] - indices[0] + 1 - len(indices)


def test_scene_depends_only_on_seed_and_index(sparse_root, tmp_path, monkeypatch):
    import setdiff_bench.synthetic.sparse as sparse

    with torch_threads(1):
        again = generate_sparse_scene(tmp_path, tiny_preset(), 3, 1)
        other = build_sparse_scene(tiny_preset(), 3, 2)
    assert file_hashes(sparse_root / "sparse_0003_01") == file_hashes(again)
    first = build_sparse_scene(tiny_preset(), 3, 1)
    assert not np.allclose(first.walk.positions, other.walk.positions)  # another index, another scene
    same_shape = first.static.means.shape == other.static.means.shape
    assert not (same_shape and torch.equal(first.static.means, other.static.means))
    monkeypatch.setitem(sparse.SPARSE_PRESETS, "sparse_tiny", tiny_preset())  # scene.json names the preset
    assert torch.equal(static_world(again).means, first.static.means)


def test_walk_goes_around_the_plaza():
    preset = get_sparse_preset("sparse")
    build = build_sparse_scene(preset, 0, 0)
    walk = build.walk
    assert walk.positions.shape == (preset.frames, 3)
    around = np.unwrap(
        np.arctan2(walk.positions[:, 1] - walk.center[1], walk.positions[:, 0] - walk.center[0])
    )
    assert abs(math.degrees(around[-1] - around[0])) > 120  # around the centre: arc_deg 150 ± 10 %
    assert walk.positions[:, 2].min() > 1.3 and walk.positions[:, 2].max() < 1.8  # handheld height varies
    assert np.ptp(walk.positions[:, 2]) > 0.2
    step = np.linalg.norm(np.diff(walk.positions[:, :2], axis=0), axis=1)
    assert step.max() < 0.5  # a walk: smooth, no jumps between frames


def test_synth_cli_writes_fits_for_the_sparse_views(tmp_path, monkeypatch):
    import setdiff_bench.synthetic.sparse as sparse

    monkeypatch.setitem(sparse.SPARSE_PRESETS, "sparse_tiny", replace(tiny_preset(), views=(3,)))
    from setdiff_bench.cli.synth import make_scene

    message = make_scene(tmp_path, "sparse_tiny", 0, 0, 1, fit=True, device="cpu", overwrite=False, threads=1)
    assert "n3" in message
    assert (tmp_path / "sparse_0000_00" / "fits" / "n3.ply").is_file()
    assert not (tmp_path / "sparse_0000_00" / "fits" / "n3.checkpoint").exists()


def test_reference_ceiling_on_a_tiny_scene(tmp_path, monkeypatch):
    import setdiff_bench.synthetic.sparse as sparse

    monkeypatch.setitem(sparse.SPARSE_PRESETS, "sparse_tiny", tiny_preset())  # the world is rebuilt by name
    sys.path.insert(0, str(REPO))
    from benchmarks.reference_ceiling import summary, target_measures
    from setdiff_bench.packets.prepare import prepare
    from setdiff_bench.packets.store import PacketStore

    with torch_threads(1):
        scene = generate_sparse_scene(tmp_path / "scenes", tiny_preset(), 0, 0)
        fit_sparse_scene(scene, replace(tiny_preset(), views=(3,)))
        prepare(
            "dl3dv",
            root=tmp_path / "scenes",
            protocol=str(SPARSE_PROTOCOL),
            fits=tmp_path / "scenes",
            out=tmp_path / "packets",
            groups=["n3"],
            progress=False,
        )
        store = PacketStore(tmp_path / "packets")
        records = []
        for packet_id in store.packet_ids("test"):  # sparse_0000_00 is a declared test scene
            records += target_measures(store, packet_id, tmp_path / "scenes", {}, [1, 3], [0.03])
    assert records
    result = summary(records, [1, 3])
    assert result["references"] == 3
    for key in ("visible_truth_1", "visible_truth_3", "visible_truth_all"):
        assert result[key] >= result["identity"] - 1e-9  # replacing seen pixels by the truth never hurts
    assert result["visible_truth_3"] >= result["visible_truth_1"] - 1e-9
    assert result["seen_all"] == pytest.approx(result["seen_3"])
    assert 0.0 <= result["error_share_all"] <= 1.0
    assert result["seen_1"] > 0.0  # the references do see the targets' surfaces


def test_synth_verb_makes_a_sparse_scene_with_its_fits(tmp_path, capsys):
    """`synth --preset sparse_tiny` goes through the same make_scene as the driving presets: one summary line
    naming the scene and each of the n3 / n6 / n9 fits, whose PLYs exist."""
    from setdiff_bench.cli.main import main

    assert (
        main(["synth", "--preset", "sparse_tiny", "--out", str(tmp_path), "--indices", "0", "--no-progress"])
        == 0
    )
    summary = [line for line in capsys.readouterr().out.splitlines() if line.startswith("sparse_0000_00:")]
    assert len(summary) == 1 and all(f"n{k}: " in summary[0] for k in (3, 6, 9)), summary
    assert sorted(p.name for p in (tmp_path / "sparse_0000_00" / "fits").glob("*.ply")) == [
        "n3.ply",
        "n6.ply",
        "n9.ply",
    ]
