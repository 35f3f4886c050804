"""The procedural world: street plan, Gaussians, markings, drives and the moving vehicle."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from setdiff_bench.gaussians.render import render
from setdiff_bench.io.images import read_mask, read_rgb
from setdiff_bench.synthetic.capture import posed_vehicle
from setdiff_bench.synthetic.generate import build_scene
from setdiff_bench.synthetic.layout import LANE_WIDTH_M, random_layout
from setdiff_bench.synthetic.presets import get_preset
from setdiff_bench.synthetic.rig import RIG, rig_camera
from setdiff_bench.synthetic.world import CATEGORIES, road_texture
from tests.synthetic.synthetic_fixtures import SEED, small_preset


@pytest.mark.parametrize("seed", range(6))
def test_street_plan(seed):
    layout = random_layout(np.random.default_rng(seed), -10.0, 70.0)
    assert layout.num_lanes >= 3 and layout.lane_width == LANE_WIDTH_M == 3.5
    # cross-section order, right to left: façade < curb < lanes < curb < façade
    assert layout.facade_right < layout.curb_right < layout.road_right < layout.road_left < layout.curb_left
    assert layout.curb_left < layout.facade_left
    for buildings in (layout.buildings_right, layout.buildings_left):
        assert buildings[0].x0 <= layout.x_min and buildings[-1].x0 + buildings[-1].width >= layout.x_max
        assert all(b.height >= 7.0 and b.style.door_positions for b in buildings)
    assert layout.poles and layout.parked_cars
    for car in layout.parked_cars:  # parked in the parking strips, not on the lanes
        assert car.y < layout.road_right or car.y > layout.road_left


def test_scenes_vary_with_the_seed():
    layouts = [random_layout(np.random.default_rng(s), -10.0, 70.0) for s in range(8)]
    assert len({layout.num_lanes for layout in layouts}) > 1
    assert len({layout.buildings_right[0].style.pattern for layout in layouts}) > 1
    assert len({round(layout.asphalt_color[0], 4) for layout in layouts}) == 8
    assert any(layout.trees for layout in layouts) and any(layout.crosswalk_x for layout in layouts)


def test_world_has_every_category_and_a_moderate_size():
    build = build_scene(get_preset("default"), 0, 0)
    counts = torch.bincount(build.world.categories, minlength=len(CATEGORIES))
    assert (counts > 0).all(), dict(zip(CATEGORIES, counts.tolist()))
    assert 10_000 < len(build.world.static) < 45_000
    assert build.world.static.sh_degree == 0
    opacities = build.world.static.opacities
    assert float(opacities.min()) > 0 and float(opacities.max()) < 1


def test_lane_markings_are_painted_on_lane_boundaries():
    layout = random_layout(np.random.default_rng(3), -10.0, 70.0)
    texture = road_texture(layout, np.random.default_rng(0), layout.road_right)
    x = np.linspace(0.0, 30.0, 301)
    on_boundary = texture(
        x - layout.x_min, np.full_like(x, LANE_WIDTH_M)
    )  # y = 1.75: lane 0 | lane 1 (dashed)
    lane_centre = texture(x - layout.x_min, np.full_like(x, LANE_WIDTH_M / 2))  # y = 0: middle of lane 0
    white = on_boundary.min(axis=1) > 0.85
    assert 0.2 < white.mean() < 0.45  # dashes: 3 m painted every 9 m
    assert (lane_centre.max(axis=1) < 0.7).all() or layout.crosswalk_x is not None
    edge = texture(x - layout.x_min, np.zeros_like(x))  # y = road_right: solid edge line
    assert (edge.min(axis=1) > 0.85).all()


def test_drives_shift_by_whole_lanes_and_cameras_by_45_degrees(scene_dir):
    build = build_scene(small_preset(), SEED, 0)
    lanes = {t.name: t for t in build.traversals}
    for name, offset in (("lane1", 1), ("lane2", 2)):
        shift = lanes[name].poses[:, 1] - lanes["lane0"].poses[:, 1]
        assert np.allclose(shift, offset * LANE_WIDTH_M, atol=0.3)
    turn = lanes["turn"].poses
    assert abs(turn[0, 1]) < 0.3 and turn[-1, 1] > LANE_WIDTH_M - 0.3  # starts in lane 0, ends in lane 1 or 2
    front, left, right = (rig_camera(lanes["lane0"], 1, spec, 80, 48) for spec in RIG)

    def yaw(camera):  # heading of the optical axis in the ground plane
        return math.degrees(math.atan2(camera.view_direction[1], camera.view_direction[0]))

    assert yaw(left) - yaw(front) == pytest.approx(45.0, abs=1e-6)
    assert yaw(right) - yaw(front) == pytest.approx(-45.0, abs=1e-6)
    assert np.allclose(front.center, right.center)


def test_moving_vehicle_follows_its_trajectory():
    build = build_scene(small_preset(), SEED, 0)
    template, vehicle = build.world.vehicles["lane0"], build.moving["lane0"]
    a, b = posed_vehicle(template, vehicle, 0.0), posed_vehicle(template, vehicle, 0.5)
    delta = (b.means - a.means).mean(dim=0)
    assert delta[0].item() == pytest.approx(0.5 * vehicle.speed_mps, abs=1e-4)
    assert vehicle.speed_mps < 0  # oncoming
    assert torch.allclose(a.means.mean(dim=0)[1], torch.tensor(vehicle.car.y, dtype=torch.float32), atol=0.3)


def test_dynamic_mask_covers_what_the_vehicle_changes(scene_dir):
    """Pixels where the ground truth differs from a render of the static world alone must be masked."""
    preset = small_preset()
    build = build_scene(preset, SEED, 0)
    checked = 0
    for path in sorted((scene_dir / "dynamic_masks").iterdir()):
        keep = read_mask(path)
        if keep.all():
            continue
        traversal, rest = path.stem.split("_", 1)
        sensor, index = rest.rsplit("_", 1)
        spec = next(s for s in RIG if s.name == sensor)
        camera = rig_camera(
            next(t for t in build.traversals if t.name == traversal),
            int(index),
            spec,
            preset.width,
            preset.height,
        )
        with torch.no_grad():
            static = render(build.world.static, [camera]).rgb[0].clamp(0, 1).permute(1, 2, 0).numpy()
        truth = read_rgb(scene_dir / "images" / (path.stem + ".png"))
        changed = np.abs(truth - static).max(axis=2) > 0.1
        assert changed.any()
        assert (changed & keep).sum() <= 0.02 * changed.sum() + 2  # changes lie inside the mask
        checked += 1
        if checked == 3:
            break
    assert checked > 0
