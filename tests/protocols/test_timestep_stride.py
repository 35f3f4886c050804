"""drivestudio-style interpolation split (``timestep_stride``) on a hand-made two-camera scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import ProtocolError
from setdiff_bench.protocols import load_protocol
from setdiff_bench.protocols.rules import RULES, timesteps_us
from setdiff_bench.protocols.schema import Table
from setdiff_bench.types import Frame, Scene

CAM = Camera(np.eye(3), np.eye(4), 8, 8)


def _frame(sensor: str, t_ms: int, key: bool) -> Frame:
    return Frame(
        f"{sensor}/{t_ms:04d}.jpg",
        Path("/x.jpg"),
        CAM,
        timestamp_us=t_ms * 1000,
        sensor=sensor,
        metadata={"is_key_frame": key},
    )


def _scene() -> Scene:
    front = [_frame("F", t, t % 500 == 0) for t in range(0, 1001, 100)]  # 0.0 .. 1.0 s, keys 0/0.5/1
    back = [_frame("B", t + 40, False) for t in range(0, 1001, 100)]  # 40 ms later
    return Scene("nuscenes", "s", Path("/"), tuple(front + back))


def test_timesteps_insert_even_steps_between_keyframes():
    assert timesteps_us([0, 500_000, 1_000_000], 4) == [
        0,
        100_000,
        200_000,
        300_000,
        400_000,
        500_000,
        600_000,
        700_000,
        800_000,
        900_000,
        1_000_000,
    ]
    assert timesteps_us([0, 500_000], 0) == [0, 500_000]


def test_every_stride_th_timestep_is_held_out_on_every_camera():
    rule = RULES["timestep_stride"]
    params = rule.validate(Table({"sensors": ["F", "B"], "stride": 3, "interpolate": 4}, Path("t.toml")))
    assert params["first"] == 2  # stride - 1 (drivestudio@7759550e)
    frames = rule.select(_scene(), params)
    # 11 timesteps 0..10; test steps 2, 5, 8 -> 0.2, 0.5, 0.8 s; B's nearest frames are 40 ms later
    assert [f.name for f in frames.targets] == [
        "F/0200.jpg",
        "F/0500.jpg",
        "F/0800.jpg",
        "B/0240.jpg",
        "B/0540.jpg",
        "B/0840.jpg",
    ]
    assert len(frames.fit) == 16 and not {f.name for f in frames.fit} & {f.name for f in frames.targets}
    params = rule.validate(
        Table({"sensors": ["F"], "stride": 3, "first": 3, "interpolate": 4}, Path("t.toml"))
    )
    assert [f.name for f in rule.select(_scene(), params).targets] == [
        "F/0300.jpg",
        "F/0600.jpg",
        "F/0900.jpg",
    ]


def test_bad_parameters_name_the_key():
    rule = RULES["timestep_stride"]
    with pytest.raises(ProtocolError, match="first"):
        rule.validate(Table({"sensors": ["F"], "stride": 3, "first": 4}, Path("t.toml")))


def test_packaged_protocol_and_evaluation_tables():
    protocol = load_protocol("nuscenes_drivestudio")
    assert protocol.groups[0].params["stride"] == 10 and protocol.groups[0].params["interpolate"] == 4
    assert load_protocol("euvs").evaluation == ("paper", "euvs_official")
    assert load_protocol("dl3dv").evaluation == ("paper", "dl3dv_3dgs_enhancer")
    assert load_protocol("nuscenes").evaluation == ("paper",)


def test_on_loaded_nuscenes_every_camera_is_held_out_at_the_same_timesteps(tmp_path):
    from dataclasses import replace

    from setdiff_bench.loaders import load_scenes
    from tests.loaders.loader_fixtures import build_nuscenes

    build_nuscenes(tmp_path, np.random.default_rng(0)).write()
    protocol = load_protocol("nuscenes_drivestudio")
    scene = load_scenes("nuscenes", tmp_path, ["scene-0061"], **dict(protocol.loader_options))[0]
    group = replace(protocol.groups[0], params={**protocol.groups[0].params, "stride": 3, "first": 2})
    frames = group.select(scene)
    assert frames.targets and frames.fit
    assert {f.sensor for f in frames.targets} == set(scene.sensors)
    assert not {f.name for f in frames.fit} & {f.name for f in frames.targets}
