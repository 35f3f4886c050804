"""Group rules: which frames of a scene a 3DGS is fitted on, and which frames are its targets.

A protocol group names one rule and its parameters (``protocols/*.toml``).  Each rule validates its
parameters when the protocol is loaded (a bad value is a ``ProtocolError`` naming the file and key)
and selects frames from a loaded :class:`~setdiff_bench.types.Scene`.  Fit frames double as the
candidates for reference views (they are the clean captures the 3DGS saw).  Targets keep the
scene's frame order (the loader's documented order: time within a traversal/camera).

Rules
-----
``test_set`` (EUVS)
    targets = frames the dataset marks ``split == "test"`` (``test_set.txt``); fit = every other
    frame of the model (docs/datasets.md, "EUVS train/test split": the baseline trains on all non-test model images).
``lanes`` (Para-Lane)
    fit = ``fit_frames`` frames of lane ``train_lane``, targets = ``target_frames`` frames of lane
    ``target_lane`` (lane = ``Frame.metadata["lane"]``), both sampled uniformly by
    :func:`uniform_indices`: ``np.linspace(0, n − 1, k).round()`` (numpy rounds halves to even) over
    the lane's frames in time order; all ``n`` frames when ``n <= k``.
``time_window`` (nuScenes)
    ``t0`` = the earliest ``timestamp_us`` among the scene's frames on ``sensors``; a frame's offset is
    ``timestamp_us − t0`` in integer microseconds.  fit = frames with offset in
    ``[fit_window[0], fit_window[1])`` seconds, targets = offset in ``[target_window[0],
    target_window[1])`` — half-open, so a frame exactly at 11 s is in the 11–12 s bucket, and one at
    15 s is in none.  ``targets = "keyframes"`` keeps only annotated keyframes (2 Hz, all six cameras
    at nearly the same instant) as targets; ``"all"`` keeps sweeps too.  Fit frames always include sweeps.
``sparse_views`` (DL3DV, 3DGS-Enhancer)
    with ``N`` frames in name order and ``n`` views: ``gap`` = the first of ``gaps`` (50, 25) with
    ``gap · n <= N``, else ``⌊N / n⌋``; fit = indices ``0, gap, …, (n − 1)·gap``; targets = every
    frame strictly between the first and last fit frame that is not a fit frame
    (xiliu8006/3dgs_dataset_generator ``select_lr_cams`` and ``render_lr_hr_pairs``).
``timestep_stride`` (nuScenes, drivestudio/OmniRe interpolation split)
    timesteps are the ``sensors[0]`` keyframe instants, each gap between consecutive keyframes split
    into ``interpolate + 1`` equal steps (drivestudio's ``--interpolate_N``, 4 → 10 Hz); at each timestep
    every sensor contributes its frame nearest in time.  Test timesteps are ``first, first + stride, …``
    (ziyc/drivestudio ``datasets/driving_dataset.py:split_train_test``: ``first = stride − 1`` at
    commit 7759550e, ``stride`` in other versions); their frames are the targets, the frames of every
    other timestep the fit (a frame nearest to both kinds of timestep is a target only).
``holdout_every`` (generic COLMAP / nerfstudio captures, the Mip-NeRF 360 / 3DGS convention)
    frames in name order; targets = indices ``0, every, 2·every, …`` (``every`` = 8), fit = the rest.
``select`` (synthetic)
    fit and targets are filters over frame attributes: ``split``, ``sensor``, ``traversal`` and
    metadata keys ``lane_offset``, ``traversal_kind``; a filter value may be a list (any of).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from setdiff_bench.errors import ProtocolError
from setdiff_bench.types import Frame, Scene

from .schema import Table

MICROSECONDS = 1_000_000
SELECT_KEYS = ("split", "sensor", "traversal", "lane_offset", "traversal_kind")


@dataclass(frozen=True)
class GroupFrames:
    """The frames one group uses in one scene.

    Attributes:
        fit: frames the group's 3DGS is fitted on (and reference candidates), scene order.
        targets: frames rendered and enhanced, scene order.
    """

    fit: tuple[Frame, ...]
    targets: tuple[Frame, ...]


@dataclass(frozen=True)
class Rule:
    """A group rule: ``validate(table) -> params`` at load time, ``select(scene, params)`` at use."""

    name: str
    validate: Callable[[Table], dict[str, Any]]
    select: Callable[[Scene, Mapping[str, Any]], GroupFrames]


def uniform_indices(n: int, k: int) -> list[int]:
    """``k`` indices spread uniformly over ``range(n)``, both ends included; ``range(n)`` when ``n <= k``.

    ``np.linspace(0, n − 1, k).round()`` (half to even).  Example: ``n = 10, k = 4`` → ``[0, 3, 6, 9]``.
    """
    if n <= k:
        return list(range(n))
    if k == 1:
        return [0]
    picked = [int(i) for i in np.linspace(0, n - 1, k).round()]
    assert len(set(picked)) == k, (n, k, picked)
    return picked


def sparse_view_indices(num_frames: int, views: int, gaps: Sequence[int] = (50, 25)) -> list[int]:
    """3DGS-Enhancer's training-view positions: ``[i · gap for i in range(views)]`` (rule in module doc)."""
    gap = next((g for g in gaps if g * views <= num_frames), num_frames // views)
    if gap < 1:
        raise ValueError(f"{num_frames} frames cannot hold {views} sparse views")
    return [i * gap for i in range(views)]


# ---------------------------------------------------------------------- test_set
def _validate_test_set(table: Table) -> dict[str, Any]:
    table.check_keys(())
    return {}


def _select_test_set(scene: Scene, params: Mapping[str, Any]) -> GroupFrames:
    return GroupFrames(
        fit=tuple(f for f in scene.frames if f.split != "test"),
        targets=tuple(f for f in scene.frames if f.split == "test"),
    )


# ---------------------------------------------------------------------- lanes
def _validate_lanes(table: Table) -> dict[str, Any]:
    table.check_keys(("train_lane", "target_lane", "fit_frames", "target_frames"))
    params = {
        "train_lane": table.integer("train_lane", minimum=0),
        "target_lane": table.integer("target_lane", minimum=0),
        "fit_frames": table.integer("fit_frames", minimum=1),
        "target_frames": table.integer("target_frames", minimum=1),
    }
    if params["train_lane"] == params["target_lane"]:
        raise table.error("target_lane", "must differ from train_lane (targets would be fit frames)")
    return params


def _select_lanes(scene: Scene, params: Mapping[str, Any]) -> GroupFrames:
    def lane(index: int, count: int) -> tuple[Frame, ...]:
        frames = [f for f in scene.frames if f.metadata.get("lane") == index]
        return tuple(frames[i] for i in uniform_indices(len(frames), count))

    return GroupFrames(
        fit=lane(params["train_lane"], params["fit_frames"]),
        targets=lane(params["target_lane"], params["target_frames"]),
    )


# ---------------------------------------------------------------------- time_window
def _window_us(table: Table, name: str) -> tuple[int, int]:
    start, end = table.numbers(name, 2)
    if not 0 <= start < end:
        raise table.error(name, f"expected [start, end) seconds with 0 <= start < end, got {[start, end]}")
    return round(start * MICROSECONDS), round(end * MICROSECONDS)


def _validate_time_window(table: Table) -> dict[str, Any]:
    table.check_keys(("sensors", "fit_window", "target_window", "targets"))
    params = {
        "sensors": table.strings("sensors"),
        "fit_window": _window_us(table, "fit_window"),
        "target_window": _window_us(table, "target_window"),
        "targets": table.string("targets", "keyframes", choices=("keyframes", "all")),
    }
    fit, target = params["fit_window"], params["target_window"]
    if target[0] < fit[1] and fit[0] < target[1]:
        raise table.error("target_window", "overlaps fit_window (targets would be fit frames)")
    return params


def time_offsets_us(scene: Scene, sensors: Sequence[str]) -> list[tuple[int, Frame]]:
    """``(timestamp_us − t0, frame)`` for the scene's frames on ``sensors`` (``t0`` = earliest of them)."""
    frames = [f for f in scene.frames if f.sensor in sensors]
    if not frames:
        return []
    untimed = [f.name for f in frames if f.timestamp_us is None]
    if untimed:
        raise ProtocolError(
            f"scene {scene.name!r}: frame {untimed[0]!r} has no timestamp; the time_window rule "
            "needs timestamps",
            scene.root,
        )
    t0 = min(int(f.timestamp_us) for f in frames)  # type: ignore[arg-type]
    return [(int(f.timestamp_us) - t0, f) for f in frames]  # type: ignore[arg-type]


def _select_time_window(scene: Scene, params: Mapping[str, Any]) -> GroupFrames:
    offsets = time_offsets_us(scene, params["sensors"])
    (f0, f1), (t0, t1) = params["fit_window"], params["target_window"]
    fit = tuple(f for dt, f in offsets if f0 <= dt < f1)
    targets = tuple(
        f
        for dt, f in offsets
        if t0 <= dt < t1 and (params["targets"] == "all" or bool(f.metadata.get("is_key_frame", True)))
    )
    return GroupFrames(fit=fit, targets=targets)


# ---------------------------------------------------------------------- sparse_views
def _validate_sparse_views(table: Table) -> dict[str, Any]:
    table.check_keys(("views", "gaps"))
    return {"views": table.integer("views", minimum=2), "gaps": table.integers("gaps", [50, 25], minimum=1)}


def _select_sparse_views(scene: Scene, params: Mapping[str, Any]) -> GroupFrames:
    frames = scene.frames
    if len(frames) < params["views"]:
        return GroupFrames(fit=(), targets=())
    fit_idx = sparse_view_indices(len(frames), params["views"], params["gaps"])
    chosen = set(fit_idx)
    targets = tuple(frames[i] for i in range(fit_idx[0] + 1, fit_idx[-1]) if i not in chosen)
    return GroupFrames(fit=tuple(frames[i] for i in fit_idx), targets=targets)


# ---------------------------------------------------------------------- timestep_stride
def _validate_timestep_stride(table: Table) -> dict[str, Any]:
    table.check_keys(("sensors", "stride", "first", "interpolate"))
    stride = table.integer("stride", minimum=2)
    params = {
        "sensors": table.strings("sensors"),
        "stride": stride,
        "first": table.integer("first", stride - 1, minimum=0),
        "interpolate": table.integer("interpolate", 4, minimum=0),
    }
    if params["first"] > stride:
        raise table.error("first", f"expected an integer <= stride ({stride}), got {params['first']}")
    return params


def timesteps_us(keyframes_us: Sequence[int], interpolate: int) -> list[int]:
    """Keyframe instants with ``interpolate`` evenly spaced instants inserted in each gap (integer µs, floor)."""
    keys = sorted(keyframes_us)
    out: list[int] = []
    for start, end in itertools.pairwise(keys):
        out += [start + (end - start) * j // (interpolate + 1) for j in range(interpolate + 1)]
    return out + keys[-1:]


def _select_timestep_stride(scene: Scene, params: Mapping[str, Any]) -> GroupFrames:
    sensors = params["sensors"]
    by_sensor = {
        s: sorted(
            (f for f in scene.frames if f.sensor == s and f.timestamp_us is not None),
            key=lambda f: int(f.timestamp_us),
        )
        for s in sensors
    }  # type: ignore[arg-type]
    keys = [
        int(f.timestamp_us)
        for f in by_sensor[sensors[0]]  # type: ignore[arg-type]
        if bool(f.metadata.get("is_key_frame", True))
    ]
    steps = timesteps_us(keys, params["interpolate"])
    test_steps = set(range(params["first"], len(steps), params["stride"]))

    def nearest(frames: Sequence[Frame], t: int) -> Frame | None:
        return min(frames, key=lambda f: (abs(int(f.timestamp_us) - t), f.name)) if frames else None  # type: ignore[arg-type]

    targets: dict[str, Frame] = {}
    fit: dict[str, Frame] = {}
    for index, t in enumerate(steps):
        for sensor in sensors:
            frame = nearest(by_sensor[sensor], t)
            if frame is not None:
                (targets if index in test_steps else fit)[frame.name] = frame
    order = {f.name: i for i, f in enumerate(scene.frames)}

    def pick(chosen: Mapping[str, Frame]) -> tuple[Frame, ...]:
        return tuple(sorted(chosen.values(), key=lambda f: order[f.name]))

    return GroupFrames(fit=pick({k: v for k, v in fit.items() if k not in targets}), targets=pick(targets))


# ---------------------------------------------------------------------- holdout_every
def _validate_holdout_every(table: Table) -> dict[str, Any]:
    table.check_keys(("every",))
    return {"every": table.integer("every", 8, minimum=2)}


def _select_holdout_every(scene: Scene, params: Mapping[str, Any]) -> GroupFrames:
    every = params["every"]
    return GroupFrames(
        fit=tuple(f for i, f in enumerate(scene.frames) if i % every != 0),
        targets=tuple(f for i, f in enumerate(scene.frames) if i % every == 0),
    )


# ---------------------------------------------------------------------- select
def _filter(table: Table, name: str) -> dict[str, tuple[Any, ...]]:
    sub = table.table(name)
    sub.check_keys(SELECT_KEYS)
    out: dict[str, tuple[Any, ...]] = {}
    for key, value in sub.data.items():
        values = value if isinstance(value, list) else [value]
        if not values or not all(isinstance(v, str | int) and not isinstance(v, bool) for v in values):
            raise sub.error(key, f"expected a string, an integer or a list of them, got {value!r}")
        out[key] = tuple(values)
    if not out:
        raise table.error(name, "empty filter: name at least one of " + ", ".join(SELECT_KEYS))
    return out


def _validate_select(table: Table) -> dict[str, Any]:
    table.check_keys(("fit", "targets"))
    return {"fit": _filter(table, "fit"), "targets": _filter(table, "targets")}


def frame_attribute(frame: Frame, key: str) -> Any:
    """A frame's value for a ``select`` filter key (attributes first, then metadata)."""
    if key in ("split", "sensor", "traversal"):
        return getattr(frame, key)
    return frame.metadata.get(key)


def matches(frame: Frame, where: Mapping[str, Sequence[Any]]) -> bool:
    """Whether ``frame`` passes every filter of ``where``."""
    return all(frame_attribute(frame, key) in values for key, values in where.items())


def _select_select(scene: Scene, params: Mapping[str, Any]) -> GroupFrames:
    return GroupFrames(
        fit=tuple(f for f in scene.frames if matches(f, params["fit"])),
        targets=tuple(f for f in scene.frames if matches(f, params["targets"])),
    )


RULES: dict[str, Rule] = {
    rule.name: rule
    for rule in (
        Rule("test_set", _validate_test_set, _select_test_set),
        Rule("lanes", _validate_lanes, _select_lanes),
        Rule("time_window", _validate_time_window, _select_time_window),
        Rule("sparse_views", _validate_sparse_views, _select_sparse_views),
        Rule("holdout_every", _validate_holdout_every, _select_holdout_every),
        Rule("select", _validate_select, _select_select),
        Rule("timestep_stride", _validate_timestep_stride, _select_timestep_stride),
    )
}
