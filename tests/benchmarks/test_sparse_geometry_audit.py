"""The pieces of ``benchmarks/sparse_geometry_audit.py`` against hand-derived values, and the whole audit on a
tiny sparse walk whose packet carries the *true* C-maps in place of the fit's (so fit = truth exactly).
"""

from __future__ import annotations

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from benchmarks.reference_ceiling import cmap_depths
from benchmarks.sparse_geometry_audit import (
    Histogram,
    fit_world_cmaps,
    nearest_reference_tokens,
    relative_errors,
)
from setdiff_bench.geometry import normalize_packet
from tests.evaluation.run.store_fixtures import HEIGHT, WIDTH, camera_at, plane_view

REPO = Path(__file__).resolve().parents[2]
DEPTH = 2.5


def test_histogram_quantiles_of_known_values() -> None:
    """Half the values 0.001 and half 0.1: the median is 0.001 and p90 0.1, within a bin (1.2 %)."""
    histogram = Histogram()
    histogram.add(np.full(50, 0.001))
    histogram.add(np.full(50, 0.1))
    assert histogram.quantile(0.5) == pytest.approx(0.001, rel=0.012)
    assert histogram.quantile(0.9) == pytest.approx(0.1, rel=0.012)
    assert histogram.summary()["pixels"] == 100
    assert math.isnan(Histogram().quantile(0.5))


def test_cmap_depths_of_a_plane_are_its_depth() -> None:
    """A C-map of the plane z = 2.5 seen head-on (alpha 0.8, C-map = alpha × point): depth 2.5 everywhere."""
    camera = camera_at(0.3)
    _, points, _ = plane_view(camera, DEPTH)
    alpha = torch.full((1, 1, HEIGHT, WIDTH), 0.8)
    cmaps = torch.from_numpy(points.transpose(2, 0, 1).copy())[None] * alpha
    depths, valid = cmap_depths([camera], cmaps, alpha)
    assert bool(valid.all())
    torch.testing.assert_close(depths, torch.full_like(depths, DEPTH), rtol=1e-5, atol=1e-5)
    _, low = cmap_depths([camera], cmaps, torch.full_like(alpha, 0.4))  # below the 0.5 threshold
    assert not bool(low.any())


def test_relative_error_of_a_depth_ten_percent_too_far() -> None:
    """Fit depth 1.1 × true depth on a pixel's ray: ‖X_fit − X_true‖ / z = 0.1 · ‖(x_n, y_n, 1)‖."""
    camera = camera_at(0.0)
    true_depth = torch.full((1, HEIGHT, WIDTH), 2.0)
    both = torch.zeros(1, HEIGHT, WIDTH, dtype=torch.bool)
    both[0, 3, 5] = both[0, 16, 24] = True
    errors = relative_errors(camera, 1.1 * true_depth, true_depth, both)
    focal = 0.9 * WIDTH
    for error, (row, col) in zip(errors, [(3, 5), (16, 24)], strict=True):
        xn, yn = (col + 0.5 - WIDTH / 2) / focal, (row + 0.5 - HEIGHT / 2) / focal
        assert error == pytest.approx(0.1 * math.sqrt(1 + xn**2 + yn**2), rel=1e-6)


def test_nearest_reference_tokens_skip_invalid_ones() -> None:
    """Two references of 2 tokens, one target of 2 tokens; the nearest valid reference token by hand."""
    points = torch.tensor(
        [
            [[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]],  # reference 0: tokens 0, 1
            [[0.1, 0.0, 0.0], [9.0, 0.0, 0.0]],  # reference 1: tokens 2, 3 (token 2 invalid)
            [[0.1, 0.0, 0.0], [8.0, 0.0, 0.0]],  # target
        ]
    )
    valid = torch.tensor([[True, True], [False, True], [True, True]])
    index, distance = nearest_reference_tokens(points, valid, 2)
    assert index.tolist() == [0, 3]
    torch.testing.assert_close(distance, torch.tensor([0.1, 1.0], dtype=torch.float64))


def test_fit_world_cmaps_undo_the_packet_normalisation() -> None:
    """World C-maps normalised as ``prepare`` does (first target's frame, unit extent) come back unchanged."""
    from setdiff_bench.types import Packet, ViewSet

    cameras = [camera_at(-0.4), camera_at(0.1, yaw_deg=10.0), camera_at(0.5)]
    points = [torch.from_numpy(plane_view(c, DEPTH)[1].transpose(2, 0, 1).copy()) for c in cameras]
    alphas = torch.full((3, 1, HEIGHT, WIDTH), 0.9)
    world = torch.stack(points) * alphas
    normalized = normalize_packet(cameras, world, 1, alphas=alphas)

    def views(part: slice) -> ViewSet:
        return ViewSet(
            images=torch.zeros(len(cameras[part]), 3, HEIGHT, WIDTH),
            cameras=normalized.cameras[part],
            cmaps=normalized.cmaps[part],
            alphas=alphas[part],
            names=tuple(f"v{i}" for i in range(len(cameras[part]))),
        )

    packet = Packet.from_key(_key(), views(slice(0, 1)), views(slice(1, None)), scale=normalized.scale)
    back, back_alphas = fit_world_cmaps(packet, cameras)
    torch.testing.assert_close(back, world, rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(back_alphas, alphas)


def _key():
    from setdiff_bench.types import PacketKey

    return PacketKey("p", "synthetic", "synthetic", "lane+1", "test", "scene_a")


def test_the_audit_of_a_packet_with_the_true_cmaps_finds_no_error(tmp_path, monkeypatch) -> None:
    """A tiny walk's n3 packet with its fit C-maps and alphas replaced by the true world's (normalised as
    ``prepare`` does): the C-map error is 0, the fit ceiling equals the true one, every token agrees."""
    sys.path.insert(0, str(REPO))
    import benchmarks.sparse_geometry_audit as audit
    import setdiff_bench.synthetic.sparse as sparse
    from setdiff_bench.packets.prepare import prepare
    from setdiff_bench.packets.store import PacketStore
    from setdiff_bench.runtime.threads import torch_threads
    from setdiff_bench.synthetic.sparse import fit_sparse_scene, generate_sparse_scene, get_sparse_preset

    preset = replace(get_sparse_preset("sparse_tiny"), frames=20, views=(3,))
    preset = replace(preset, fit=preset.fit.rescaled(10))
    monkeypatch.setitem(sparse.SPARSE_PRESETS, "sparse_tiny", preset)  # the world is rebuilt by name
    with torch_threads(1):
        scene = generate_sparse_scene(tmp_path / "scenes", preset, 0, 0)
        fit_sparse_scene(scene, preset)
        prepare(
            "dl3dv",
            root=tmp_path / "scenes",
            protocol="dl3dv_sparse_synthetic",
            fits=tmp_path / "scenes",
            out=tmp_path / "packets",
            groups=["n3"],
            progress=False,
        )
        store = PacketStore(tmp_path / "packets")
        packet_id = store.packet_ids("test")[0]
        original = audit.packet_and_world

        def true_fit(*args):
            packet, truth, masks, cameras, world = original(*args)
            n = len(packet.references)
            normalized = normalize_packet(cameras, world.cmap.float(), n, alphas=world.alpha.float())
            alphas = world.alpha.float()
            packet = replace(
                packet,
                references=replace(packet.references, cmaps=normalized.cmaps[:n], alphas=alphas[:n]),
                targets=replace(packet.targets, cmaps=normalized.cmaps[n:], alphas=alphas[n:]),
            )
            return packet, truth, masks, cameras, world

        monkeypatch.setattr(audit, "packet_and_world", true_fit)
        histograms = {name: audit.Histogram() for name in ("targets_seen", "targets_unseen", "references")}
        record = audit.packet_audit(
            store, packet_id, tmp_path / "scenes", {}, [1, 3], 0.03, 3, [40, 12], histograms
        )
    for name in ("targets_seen", "references"):
        assert histograms[name].summary()["pixels"] > 0
        assert histograms[name].quantile(0.9) < 1e-4, name  # float32 round trip only
    assert record["no_fit_point"] == 0
    for fit, true in zip(record["ceiling_fit"], record["ceiling_true"], strict=True):
        for key in ("seen_3", "copy_3", "visible_truth_1"):
            assert fit[key] == pytest.approx(true[key], abs=0.02), key
    assert record["reproject_fit"] == pytest.approx(record["reproject_true"], abs=0.05)
    for tokens in ("40", "12"):
        raw = record["tokens"][tokens]["raw"]
        assert raw["valid_both"] > 0 and raw["agree"] == raw["valid_both"]
