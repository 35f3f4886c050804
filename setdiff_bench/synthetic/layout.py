"""The street plan of one synthetic scene, drawn from a seed: lanes, pavements, buildings, street
furniture, parked cars and the moving vehicles of each drive.  Pure data (metres); no Gaussians.

World frame (``scene.json`` ``world_up = [0, 0, 1]``): x along the street in the driving direction,
y to the left, z up, ground at z = 0.  Lane ``k`` (0 = rightmost, the training lane) is centred at
``y = k · lane_width``.  Lanes ``0 … ego_lanes − 1`` drive towards +x; any further lanes are oncoming.
Cross-section from right to left: façade | sidewalk | curb | parking strip | lanes | parking strip |
curb | sidewalk | façade.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from setdiff_bench.synthetic.textures import FacadeStyle

LANE_WIDTH_M = 3.5
PARKING_WIDTH_M = 2.3
CURB_HEIGHT_M = 0.15
EGO_LANES = 3


@dataclass(frozen=True)
class Building:
    """One building along a side of the street.

    Attributes:
        x0, width: extent along the street (metres).  height: metres.
        setback: extra distance of the façade behind the sidewalk edge (metres, ≥ 0).
        style: façade texture parameters.
    """

    x0: float
    width: float
    height: float
    setback: float
    style: FacadeStyle


@dataclass(frozen=True)
class Car:
    """A car: footprint centre ``(x, y)``, heading ``yaw`` (radians about +z), size and body colour."""

    x: float
    y: float
    yaw: float
    length: float
    width: float
    height: float
    color: tuple[float, float, float]


@dataclass(frozen=True)
class MovingVehicle:
    """A vehicle driving along a lane during one traversal: ``x(t) = x_start + speed · t`` at ``y``."""

    car: Car
    x_start: float
    speed_mps: float


@dataclass(frozen=True)
class Tree:
    x: float
    y: float
    trunk_height: float
    crown_radius: float
    crown_color: tuple[float, float, float]


@dataclass(frozen=True)
class Pole:
    x: float
    y: float
    height: float
    arm_direction: float  # +1 arm towards +y, −1 towards −y
    has_sign: bool


@dataclass(frozen=True)
class StreetLayout:
    """Everything placed in one scene (metres, world frame above)."""

    num_lanes: int
    lane_width: float
    x_min: float
    x_max: float
    sidewalk_right: float
    sidewalk_left: float
    asphalt_color: tuple[float, float, float]
    sidewalk_color: tuple[float, float, float]
    paving_tile: float
    buildings_right: tuple[Building, ...]
    buildings_left: tuple[Building, ...]
    trees: tuple[Tree, ...]
    poles: tuple[Pole, ...]
    parked_cars: tuple[Car, ...]
    crosswalk_x: float | None
    street_end: str  # "closed" (a building across the street) or "open" (distant skyline)
    sky_horizon: tuple[float, float, float]
    sky_zenith: tuple[float, float, float]

    # ------------------------------------------------------------------ cross-section
    @property
    def road_right(self) -> float:
        """y of the right edge of the driving lanes (start of the right parking strip)."""
        return -self.lane_width / 2

    @property
    def road_left(self) -> float:
        return (self.num_lanes - 0.5) * self.lane_width

    @property
    def curb_right(self) -> float:
        """y of the right curb face (outer edge of the parking strip)."""
        return self.road_right - PARKING_WIDTH_M

    @property
    def curb_left(self) -> float:
        return self.road_left + PARKING_WIDTH_M

    @property
    def facade_right(self) -> float:
        """y of the right building line (before setbacks)."""
        return self.curb_right - self.sidewalk_right

    @property
    def facade_left(self) -> float:
        return self.curb_left + self.sidewalk_left

    def lane_center(self, lane: int) -> float:
        return lane * self.lane_width


# ---------------------------------------------------------------------- random draws
_WALLS = [
    (0.82, 0.76, 0.66),
    (0.72, 0.42, 0.33),
    (0.86, 0.84, 0.78),
    (0.55, 0.57, 0.60),
    (0.78, 0.66, 0.48),
    (0.62, 0.36, 0.28),
    (0.90, 0.88, 0.82),
    (0.45, 0.48, 0.52),
    (0.70, 0.74, 0.70),
    (0.80, 0.60, 0.52),
]
_CAR_COLORS = [
    (0.75, 0.08, 0.08),
    (0.10, 0.18, 0.45),
    (0.85, 0.85, 0.85),
    (0.12, 0.12, 0.13),
    (0.55, 0.56, 0.58),
    (0.20, 0.40, 0.25),
    (0.90, 0.75, 0.15),
    (0.35, 0.22, 0.15),
    (0.60, 0.72, 0.85),
]
_GLASS = [(0.20, 0.27, 0.34), (0.28, 0.36, 0.42), (0.16, 0.19, 0.22), (0.30, 0.40, 0.38)]


def _jitter(
    rng: np.random.Generator, color: tuple[float, float, float], amount: float
) -> tuple[float, float, float]:
    c = np.clip(
        np.asarray(color) * (1 + rng.uniform(-amount, amount)) + rng.uniform(-amount / 2, amount / 2, 3), 0, 1
    )
    return (float(c[0]), float(c[1]), float(c[2]))


def random_style(rng: np.random.Generator, width: float) -> FacadeStyle:
    pattern = str(rng.choice(["plaster", "brick", "panels", "glass"], p=[0.35, 0.3, 0.2, 0.15]))
    wall = _WALLS[int(rng.integers(len(_WALLS)))]
    if pattern == "brick":
        wall = _WALLS[int(rng.choice([1, 5, 9]))]
    glass = _GLASS[int(rng.integers(len(_GLASS)))]
    floor_height = float(rng.uniform(2.9, 3.8))
    pitch = float(rng.uniform(1.8, 3.0))
    if pattern == "glass":
        ww, wh = pitch - 0.25, floor_height - 0.5
        wall = _jitter(rng, (0.35, 0.38, 0.42), 0.1)
    else:
        ww, wh = float(rng.uniform(0.8, min(1.6, pitch - 0.5))), float(rng.uniform(1.2, 1.9))
    n_doors = int(rng.integers(1, 3)) if width > 6 else 1
    doors = tuple(float(d) for d in np.sort(rng.uniform(1.2, max(1.3, width - 1.2), size=n_doors)))
    return FacadeStyle(
        wall=_jitter(rng, wall, 0.08),
        trim=_jitter(rng, (0.9, 0.9, 0.88) if rng.random() < 0.6 else (0.3, 0.3, 0.32), 0.05),
        glass=_jitter(rng, glass, 0.1),
        door=_jitter(rng, (0.35, 0.22, 0.12) if rng.random() < 0.5 else (0.2, 0.25, 0.3), 0.1),
        pattern=pattern,
        floor_height=floor_height,
        window_width=ww,
        window_height=wh,
        window_pitch=pitch,
        ground_floor_shop=bool(rng.random() < 0.4),
        door_positions=doors,
    )


def _buildings(rng: np.random.Generator, x_min: float, x_max: float) -> tuple[Building, ...]:
    out = []
    x = x_min - float(rng.uniform(0, 6))
    while x < x_max:
        width = float(rng.uniform(7.0, 20.0))
        height = float(rng.choice([rng.uniform(7, 12), rng.uniform(12, 22)], p=[0.55, 0.45]))
        setback = float(rng.choice([0.0, rng.uniform(0.3, 1.5)], p=[0.7, 0.3]))
        out.append(Building(x, width, height, setback, random_style(rng, width)))
        x += width + float(rng.choice([0.0, rng.uniform(1.5, 4.0)], p=[0.8, 0.2]))
    return tuple(out)


def random_car(rng: np.random.Generator, x: float, y: float, yaw: float) -> Car:
    kind = rng.random()
    length, width, height = (
        float(rng.uniform(4.0, 4.8)),
        float(rng.uniform(1.75, 1.9)),
        float(rng.uniform(1.4, 1.55)),
    )
    if kind > 0.8:  # van / SUV
        length, height = float(rng.uniform(4.6, 5.3)), float(rng.uniform(1.75, 2.0))
    return Car(
        x, y, yaw, length, width, height, _jitter(rng, _CAR_COLORS[int(rng.integers(len(_CAR_COLORS)))], 0.1)
    )


def random_layout(rng: np.random.Generator, x_min: float, x_max: float) -> StreetLayout:
    """Draw a street plan covering ``x_min … x_max`` (metres)."""
    num_lanes = int(rng.choice([4, 5], p=[0.6, 0.4]))
    sidewalk_right, sidewalk_left = float(rng.uniform(3.0, 4.5)), float(rng.uniform(3.0, 4.5))
    asphalt = _jitter(rng, (0.30, 0.30, 0.31), 0.15)
    sidewalk = _jitter(rng, (0.62, 0.60, 0.56), 0.1)
    layout_stub = StreetLayout(
        num_lanes,
        LANE_WIDTH_M,
        x_min,
        x_max,
        sidewalk_right,
        sidewalk_left,
        asphalt,
        sidewalk,
        0.0,
        (),
        (),
        (),
        (),
        (),
        None,
        "open",
        (0, 0, 0),
        (0, 0, 0),
    )
    trees: list[Tree] = []
    poles: list[Pole] = []
    for side in (-1, 1):
        curb = layout_stub.curb_right if side < 0 else layout_stub.curb_left
        if rng.random() < 0.75:
            x = x_min + float(rng.uniform(0, 6))
            spacing = float(rng.uniform(7, 12))
            while x < x_max - 4:
                trees.append(
                    Tree(
                        x,
                        curb + side * float(rng.uniform(0.9, 1.4)),
                        float(rng.uniform(2.2, 3.2)),
                        float(rng.uniform(1.3, 2.1)),
                        _jitter(rng, (0.22, 0.38, 0.16), 0.2),
                    )
                )
                x += spacing * float(rng.uniform(0.85, 1.15))
        x = x_min + float(rng.uniform(2, 10))
        spacing = float(rng.uniform(14, 22))
        while x < x_max - 4:
            pole_x = x
            if any(
                abs(t.x - pole_x) < 2.0 and np.sign(t.y - layout_stub.lane_center(1)) == side for t in trees
            ):
                pole_x += 3.0
            poles.append(
                Pole(pole_x, curb + side * 0.45, float(rng.uniform(6, 8)), -side, bool(rng.random() < 0.35))
            )
            x += spacing
    cars: list[Car] = []
    for side in (-1, 1):
        y = (
            (layout_stub.road_right - PARKING_WIDTH_M / 2)
            if side < 0
            else (layout_stub.road_left + PARKING_WIDTH_M / 2)
        )
        x = x_min + float(rng.uniform(-3, 5))
        while x < x_max - 3:
            if rng.random() < 0.7:
                car = random_car(rng, x, y + float(rng.uniform(-0.15, 0.15)), float(rng.uniform(-0.05, 0.05)))
                cars.append(car)
                x += car.length + float(rng.uniform(0.8, 2.5))
            else:
                x += float(rng.uniform(3.0, 9.0))
    crosswalk = float(rng.uniform(x_min + 0.55 * (x_max - x_min), x_max - 8)) if rng.random() < 0.6 else None
    horizon = _jitter(rng, (0.80, 0.85, 0.90), 0.05)
    zenith = _jitter(rng, (0.35, 0.52, 0.80), 0.1)
    return StreetLayout(
        num_lanes=num_lanes,
        lane_width=LANE_WIDTH_M,
        x_min=x_min,
        x_max=x_max,
        sidewalk_right=sidewalk_right,
        sidewalk_left=sidewalk_left,
        asphalt_color=asphalt,
        sidewalk_color=sidewalk,
        paving_tile=float(rng.choice([0.6, 0.8, 1.0])),
        buildings_right=_buildings(rng, x_min, x_max),
        buildings_left=_buildings(rng, x_min, x_max),
        trees=tuple(trees),
        poles=tuple(poles),
        parked_cars=tuple(cars),
        crosswalk_x=crosswalk,
        street_end=str(rng.choice(["closed", "open"])),
        sky_horizon=horizon,
        sky_zenith=zenith,
    )


def random_moving_vehicle(
    rng: np.random.Generator, layout: StreetLayout, duration_s: float, x_range: tuple[float, float]
) -> MovingVehicle:
    """An oncoming vehicle in the first oncoming lane that passes the ego vehicle's stretch of street."""
    lane = EGO_LANES
    speed = -float(rng.uniform(6.0, 11.0))
    # choose the start so that it crosses the middle of x_range around mid-drive (±30 %)
    x_mid = 0.5 * (x_range[0] + x_range[1])
    t_cross = duration_s * float(rng.uniform(0.2, 0.8))
    x_start = x_mid - speed * t_cross + float(rng.uniform(5, 15))
    car = random_car(rng, x_start, layout.lane_center(lane) + float(rng.uniform(-0.3, 0.3)), math.pi)
    return MovingVehicle(car, x_start, speed)
