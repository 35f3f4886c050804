"""DiFix reference rule: Difix3D's nearest pose (centre distance + rotation angle, 1:1) on hand-made cameras."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers import difix
from setdiff_bench.errors import UsageError
from setdiff_bench.types import Packet, ViewSet

K = np.array([[10.0, 0, 4], [0, 10.0, 4], [0, 0, 1]])


def camera(center, yaw_deg=0.0):
    a = math.radians(yaw_deg)
    c2w = np.eye(4)
    c2w[:3, :3] = [[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]]
    c2w[:3, 3] = center
    return Camera.from_c2w(c2w, K, 8, 8)


REFS = [camera((0, 0, 0)), camera((0.5, 0, 0), 90)]
# target 0: distances 0.4 + 0 = 0.4 (ref 0) vs 0.1 + pi/2 (ref 1) -> ref 0 (translation alone picks ref 1)
# target 1: 0.4 + pi/2 (ref 0) vs 0.1 + 0 (ref 1) -> ref 1
# target 2: at x = 0.25 with yaw 45: 0.25 + pi/4 to both -> tie -> first reference
TARGETS = [camera((0.4, 0, 0)), camera((0.4, 0, 0), 90), camera((0.25, 0, 0), 45)]


def test_pose_distance_and_assignments_by_hand():
    assert difix.pose_distance(REFS[0], TARGETS[0]) == pytest.approx(0.4)
    assert difix.pose_distance(REFS[1], TARGETS[0]) == pytest.approx(0.1 + math.pi / 2)
    assert difix.rotation_angle(REFS[0].R, REFS[1].R) == pytest.approx(math.pi / 2)
    assert difix.nearest_pose_assignments(REFS, TARGETS) == [0, 1, 0]
    with pytest.raises(UsageError):
        difix.nearest_pose_assignments([], TARGETS)


def _views(cameras, values):
    n = len(cameras)
    images = torch.stack([torch.full((3, 8, 8), v) for v in values])
    return ViewSet(
        tuple(f"v{i}" for i in range(n)),
        images,
        torch.zeros(n, 3, 8, 8),
        torch.ones(n, 1, 8, 8),
        tuple(cameras),
    )


@pytest.mark.parametrize(("rule", "expected"), [("nearest_pose", [0.1, 0.9, 0.1]), ("eq2", [0.1, 0.1, 0.1])])
def test_each_target_is_enhanced_with_its_rule_reference(monkeypatch, rule, expected):
    from setdiff_bench.models.setdiff import inference

    def fake_enhance(model, packet, **options):  # output = the (single) reference image it was given
        assert options["max_references"] == 1 and options["targets_per_set"] == 1
        return packet.references.images[:1].expand(len(packet.targets), -1, -1, -1).clone()

    monkeypatch.setattr(inference, "enhance_packet", fake_enhance)
    model = torch.nn.Linear(1, 1)
    config = SimpleNamespace(
        model=SimpleNamespace(guidance_scale=1.0, max_references=1, targets_per_set=1, latent_factor=8)
    )
    base = difix.ModelEnhancer("difix", model, config, "ckpt", guidance_scale=None, sets_per_call=None)
    enhancer = difix.DifixEnhancer(base, rule)
    packet = Packet(
        "p",
        "synthetic",
        "synthetic",
        "g",
        "test",
        "s",
        _views(REFS, [0.1, 0.9]),
        _views(TARGETS, [0.5, 0.5, 0.5]),
    )
    out = enhancer.enhance(packet)
    assert out[:, 0, 0, 0].tolist() == pytest.approx(expected)
    assert enhancer.options["references"] == rule


def test_unknown_rule_is_refused():
    with pytest.raises(UsageError, match="nearest_pose, eq2"):
        difix.create(checkpoint="x", references="closest")
