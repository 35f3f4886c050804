"""The sparse-view kind's tiers: ``sparse`` (fits from the whole-video points) and ``sparse_random_init`` (fits
from random points, as 3DGS-Enhancer's n-view fits), and the fit-view SfM points of the init probe."""

from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from setdiff_bench.gaussians.fit import _fit as fit_module  # where fit_views_to_ply calls fit_gaussians
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.synthetic.sparse import (
    SPARSE_PRESETS,
    build_sparse_scene,
    fit_sparse_scene,
    fit_view_points,
    generate_sparse_scene,
    get_sparse_preset,
)


def test_the_random_init_tier_is_the_sparse_walks_fitted_from_random_points() -> None:
    """Same walks, world and views as ``sparse``; only the name, the initial points and the fit length differ."""
    mild, paper = get_sparse_preset("sparse"), get_sparse_preset("sparse_random_init")
    differing = {f.name for f in fields(mild) if getattr(mild, f.name) != getattr(paper, f.name)}
    assert differing == {"name", "init", "fit"}
    assert (mild.init, paper.init) == ("sparse", "random")
    assert paper.fit.iterations > mild.fit.iterations
    assert paper.fit.strategy.max_gaussians == mild.fit.strategy.max_gaussians  # the same cap, fitted longer
    assert list(SPARSE_PRESETS)[:2] == ["sparse_tiny", "sparse"]  # the default tier keeps its place


def test_a_sparse_fit_starts_from_the_presets_initial_points(tmp_path: Path, monkeypatch) -> None:
    """``fit_sparse_scene`` hands the preset's ``init`` to the fit: ``sparse`` reads the scene's points3D,
    ``random`` never does (the points a fit receives are recorded by a stand-in for fit_gaussians)."""
    tiny = replace(get_sparse_preset("sparse_tiny"), frames=20, views=(3,))
    tiny = replace(tiny, fit=tiny.fit.rescaled(2))
    received: list[int | None] = []
    original = fit_module.fit_gaussians

    def recording(views, config, points=None, colors=None, **options):
        received.append(None if points is None else len(points))
        return original(views, config, points=points, colors=colors, **options)

    monkeypatch.setattr(fit_module, "fit_gaussians", recording)
    with torch_threads(1):
        scene = generate_sparse_scene(tmp_path, tiny, 0, 0)
        fit_sparse_scene(scene, tiny)
        fit_sparse_scene(scene, replace(tiny, init="random"), overwrite=True)
    assert received[0] is not None and received[0] > 0  # the scene's points3D
    assert received[1] is None  # random points


def test_fit_view_points_are_seen_by_two_fit_views() -> None:
    """Points of the n3 fit views: each projects inside at least two of the three views, in front of them."""
    preset = get_sparse_preset("sparse_tiny")
    build = build_sparse_scene(preset, 0, 0)
    indices = [0, 10, 20]
    with torch_threads(1):
        points = fit_view_points(build, indices)
    assert len(points.xyz) > 50 and points.rgb.dtype == np.uint8
    inside = np.zeros(len(points.xyz), int)
    for i in indices:
        camera = build.cameras[i]
        uv, z = camera.project(points.xyz)
        with np.errstate(invalid="ignore"):
            inside += (
                (z > 0)
                & (np.abs(uv[:, 0] - camera.width / 2) <= camera.width / 2 + 1)
                & (np.abs(uv[:, 1] - camera.height / 2) <= camera.height / 2 + 1)
            )
    assert (inside >= 2).mean() > 0.95  # noise may push a few points just outside a border
