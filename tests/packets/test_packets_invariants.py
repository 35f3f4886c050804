"""Every prepared packet satisfies the paper's invariants, recomputed here independently of ``prepare``.

References: the test's own world cameras (built in packet_fixtures with numpy), Eq. 2 and the
normalisation written out by hand with numpy/scipy, the fit model rendered again at the world cameras.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from scipy.spatial.distance import pdist

from setdiff_bench.gaussians.render import render
from tests.packets.packet_fixtures import HOLDOUT, STEPS

ALPHA, BETA = 0.8, 0.2


def centre(w2c: np.ndarray) -> np.ndarray:
    return -w2c[:3, :3].T @ w2c[:3, 3]


def packet_world_w2c(store, packet_id, scenes) -> tuple[list[str], list[np.ndarray], int]:
    """Frame names (references then targets), their world w2c from the fixture, and N."""
    rows = store.rows(packet_id)
    scene = scenes[rows["scene"].iloc[0]]
    names = list(rows["frame"])
    return names, [scene.cameras[n].w2c for n in names], int((rows["role"] == "ref").sum())


def test_every_packet_is_normalised_into_its_first_target(prepared, street):
    _, scenes = street
    _, _, store = prepared
    assert len(store) == 17
    for pid in store.packet_ids():
        packet = store.load_packet(pid)
        cameras = (*packet.references.cameras, *packet.targets.cameras)
        np.testing.assert_allclose(packet.targets.cameras[0].w2c, np.eye(4), atol=1e-9)
        centres = np.stack([centre(c.w2c) for c in cameras])
        assert pdist(centres).max() == pytest.approx(1.0, abs=1e-9)
        # the same similarity maps every world camera: w2c' = [R Rₐᵀ | s (t − R Rₐᵀ tₐ)]
        names, world, n = packet_world_w2c(store, pid, scenes)
        assert names == [*packet.references.names, *packet.targets.names]
        anchor = world[n]
        scale = 1.0 / pdist(np.stack([centre(w) for w in world])).max()
        assert packet.scale == pytest.approx(scale, rel=1e-12)
        for camera, w in zip(cameras, world):
            rotation = w[:3, :3] @ anchor[:3, :3].T
            np.testing.assert_allclose(camera.w2c[:3, :3], rotation, atol=1e-9)
            np.testing.assert_allclose(
                camera.w2c[:3, 3], scale * (w[:3, 3] - rotation @ anchor[:3, 3]), atol=1e-9
            )


def test_references_are_the_top_n_by_eq2(prepared, street):
    _, scenes = street
    _, _, store = prepared
    for pid in store.packet_ids():
        rows = store.rows(pid)
        scene = scenes[rows["scene"].iloc[0]]
        all_centres = np.stack([centre(c.w2c) for c in scene.cameras.values()])
        d_max = pdist(all_centres).max()
        candidates = scene.train  # fit frames = train_set.txt (lane0 front minus the held-out step)
        targets = list(rows.loc[rows["role"] == "target", "frame"])
        scores = []
        for name in candidates:
            cw = scene.cameras[name].w2c
            per_target = []
            for target in targets:
                tw = scene.cameras[target].w2c
                cos = float(cw[2, :3] @ tw[2, :3])  # optical axes = third rows of R
                distance = float(np.linalg.norm(centre(cw) - centre(tw)))
                per_target.append(ALPHA * cos + BETA * (1.0 - distance / d_max))
            scores.append(np.mean(per_target))
        order = sorted(range(len(candidates)), key=lambda i: (-scores[i], i))
        n = min(len(candidates), 6 if rows["split"].iloc[0] == "train" else 8)
        expected = [candidates[i] for i in order[:n]]
        assert list(rows.loc[rows["role"] == "ref", "frame"]) == expected, pid
        np.testing.assert_allclose(
            rows.loc[rows["role"] == "ref", "overlap_score"], [scores[i] for i in order[:n]], atol=1e-12
        )


def test_cmaps_and_alpha_are_the_fit_render_moved_into_the_packet_frame(prepared, street):
    _, scenes = street
    _, _, store = prepared
    chosen = [pid for pid in store.packet_ids() if pid.startswith("synthetic__street-02__")][:3]
    assert len(chosen) == 3
    for pid in chosen:
        packet = store.load_packet(pid)
        names, world, n = packet_world_w2c(store, pid, scenes)
        scene = scenes[packet.scene]
        all_centres = np.stack([centre(c.w2c) for c in scene.cameras.values()])
        bound, middle = pdist(all_centres).max() * 3.0, all_centres.mean(axis=0)  # cmap_clip = 3.0
        with torch.no_grad():
            out = render(
                scene.fit,
                [scene.cameras[name] for name in names],
                cmap_bound=bound,
                cmap_center=middle.tolist(),
            )
        anchor, scale = world[n], packet.scale
        cmap = out.cmap.double().numpy()
        alpha = out.alpha.double().numpy()
        expected = scale * (
            np.einsum("ij,vjhw->vihw", anchor[:3, :3], cmap) + alpha * anchor[:3, 3].reshape(1, 3, 1, 1)
        )
        stored = torch.cat([packet.references.cmaps, packet.targets.cmaps]).double().numpy()
        stored_alpha = torch.cat([packet.references.alphas, packet.targets.alphas]).double().numpy()
        np.testing.assert_allclose(stored_alpha, alpha, atol=1e-6)
        np.testing.assert_allclose(stored, expected, atol=2e-5 * max(1.0, np.abs(expected).max()))

        # A C-map point divided by alpha, projected through the normalised camera, lands exactly where
        # the world-frame point lands through the world camera: C-maps and cameras share one frame.
        checked = 0
        for v, camera in enumerate((*packet.references.cameras, *packet.targets.cameras)):
            a = stored_alpha[v, 0]
            ys, xs = np.nonzero(a > 0.98)
            packet_points = (stored[v][:, ys, xs] / a[ys, xs]).T
            world_points = (cmap[v][:, ys, xs] / alpha[v, 0][ys, xs]).T
            uv_packet = project(camera.K, camera.w2c, packet_points)
            uv_world = project(camera.K, world[v], world_points)
            np.testing.assert_allclose(uv_packet, uv_world, atol=1e-3)
            pixel = np.stack([xs + 0.5, ys + 0.5], 1)
            inside = (np.abs(world_points - middle) < bound - 1e-3).all(
                axis=1
            )  # not moved by the clipping box
            error = np.linalg.norm(uv_packet - pixel, axis=1)[inside]
            # near its pixel: a few px off because these Gaussians are 3-10 px wide and compositing favours
            # the nearer ones on oblique surfaces; a point in another frame would land anywhere
            assert np.median(error) < 0.25 * camera.width
            checked += len(xs)
        assert checked > 1000


def project(K: np.ndarray, w2c: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``(P, 2)`` pixel coordinates of ``(P, 3)`` points (pinhole, all in front of the camera)."""
    cam = points @ w2c[:3, :3].T + w2c[:3, 3]
    assert (cam[:, 2] > 0).all()
    uv = cam @ K.T
    return uv[:, :2] / uv[:, 2:]


def test_images_ground_truth_and_masks(prepared, street):
    root, scenes = street
    _, _, store = prepared
    for pid in store.packet_ids(split="test"):
        packet = store.load_packet(pid)
        scene = scenes[packet.scene]
        folder = root / packet.scene
        for name, image in zip(packet.references.names, packet.references.images):
            source = cv2.imread(str(folder / "images" / name))[:, :, ::-1]
            assert np.array_equal(np.rint(image.permute(1, 2, 0).numpy() * 255).astype(np.uint8), source)
        gt, masks = store.load_ground_truth(pid)
        assert gt.dtype == torch.float32 and masks.dtype == torch.bool
        assert gt.shape == packet.targets.images.shape and masks.shape == (len(packet.targets), 1, 32, 48)
        for i, name in enumerate(packet.targets.names):
            source = cv2.imread(str(folder / "images" / name))[:, :, ::-1]
            assert np.array_equal(np.rint(gt[i].permute(1, 2, 0).numpy() * 255).astype(np.uint8), source)
            keep = cv2.imread(str(folder / "dynamic_masks" / name), cv2.IMREAD_GRAYSCALE) > 127
            assert np.array_equal(masks[i, 0].numpy(), keep)
        with torch.no_grad():
            rendered = render(scene.fit, [scene.cameras[n] for n in packet.targets.names]).rgb
        expected = np.rint(np.clip(rendered.numpy(), 0, 1) * 255)
        stored = np.rint(packet.targets.images.numpy() * 255)
        assert np.abs(stored - expected).max() <= 1  # same render, 8-bit quantised


def test_groups_targets_sizes_and_splits(prepared, street):
    _, scenes = street
    _, summary, store = prepared
    index = store.index
    assert summary.split_counts == {"train": 2, "test": 1}
    assert set(index.loc[index["scene"] == "street_02", "split"]) == {"test"}
    assert set(index.loc[index["scene"] != "street_02", "split"]) == {"train"}
    expected_targets = {
        "lane+1": [f"lane1_front_{i:03d}.png" for i in range(STEPS)],
        "lane+2": [f"lane2_front_{i:03d}.png" for i in range(STEPS)],
        "side": [f"lane0_{c}_{i:03d}.png" for c in ("front_left", "front_right") for i in range(STEPS)],
        "turn": [f"turn_front_{i:03d}.png" for i in range(STEPS)],
        "interp": [f"lane0_front_{HOLDOUT:03d}.png"],
    }
    for scene in scenes:
        for group, names in expected_targets.items():
            rows = index[(index["scene"] == scene) & (index["group"] == group)]
            targets = rows[rows["role"] == "target"].sort_values(["packet_id", "view"])
            assert list(targets["frame"]) == names, (scene, group)  # each target once, consecutive chunks
            views = 12 if scene != "street_02" else 16
            per_packet = views - 4  # N = min(6 or 8, 4 fit frames) = 4 references
            sizes = [int((r["role"] == "target").sum()) for _, r in rows.groupby("packet_id")]
            assert all((r["role"] == "ref").sum() == 4 for _, r in rows.groupby("packet_id"))
            assert len(sizes) == -(-len(names) // per_packet) and max(sizes) - min(sizes) <= 1
    side = index[(index["scene"] == "street_00") & (index["group"] == "side") & (index["role"] == "target")]
    assert sorted(side.groupby("packet_id").size()) == [5, 5]  # 10 targets, M = 12 − 4 → two chunks of 5
    assert store.verify() == []
