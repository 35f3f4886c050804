"""Fits: the 3DGS PLY of each (scene, fit key) that a group's packets are rendered from.

``fits_dir`` (``--fits DIR``): one standard 3DGS PLY per scene and fit key, looked up as
``DIR/<scene>/<fit_key>.ply``, then ``DIR/<scene>/fits/<fit_key>.ply`` (the synthetic generator's
in-scene fits: ``--fits`` may be the dataset root).  ``<scene>`` is the loader's scene name (it may
contain ``/``, e.g. ``Level 1/nuplan_vegas_location_1``); fit keys are the protocol's: EUVS
``level1``/``level2``/``level3``, Para-Lane ``clip_0`` (the training lane), nuScenes ``first_10s``,
DL3DV ``n3``/``n6``/``n9``, synthetic ``lane0``.  The PLY must be in the loader's world frame.
``fit=True`` (``--fit``): fit each one with :func:`setdiff_bench.gaussians.fit.fit_gaussians` on the
group's fit frames (loader resolution, dataset masks), writing ``<out>/fits/<scene>/<fit_key>.ply``
(reused on a rerun; the fit itself checkpoints under ``<fit_key>.ckpt/`` and resumes).  A degraded
training-pair fit (:mod:`setdiff_bench.packets.recipes`) is the fit key ``<fit_key>@<label>``; the ``cycle``
recipe's is fitted on renders of ``<fit_key>.ply`` (made first when missing; :mod:`setdiff_bench.packets.cycle`).
"""

from __future__ import annotations

import shutil
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from setdiff_bench.errors import DatasetError, UsageError
from setdiff_bench.gaussians.fit import FitConfig, fit_views_to_ply, load_fit_views
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.packets.cycle import cycle_views
from setdiff_bench.runtime.devices import resolve_device
from setdiff_bench.types import Frame, Scene

#: 3DGS iterations of a fit made with ``--fit``: the standard schedule's (``FitConfig.iterations``).
DEFAULT_FIT_ITERATIONS: int = FitConfig().iterations


class FitSource:
    """Finds (or trains) the PLY of each (scene, fit key) and hashes it once."""

    def __init__(
        self,
        *,
        fits_dir: Path | None,
        fit: bool,
        out: Path,
        fit_iterations: int = DEFAULT_FIT_ITERATIONS,
        fit_config: FitConfig | None = None,
        fit_device: str = "auto",
        progress: bool = True,
        downscale: int = 1,
    ) -> None:
        if (fits_dir is None) == (not fit):
            raise UsageError(
                "give exactly one of --fits DIR (your 3DGS PLYs) or --fit (fit them here)", "--fits"
            )
        self.fits_dir, self.fit, self.out = fits_dir, fit, out
        self.fit_iterations, self.fit_device, self.progress = fit_iterations, fit_device, progress
        self.fit_config = fit_config  # when given: the whole fit configuration (fit_iterations unused)
        self.downscale = downscale  # fit at the protocol's working scale ([images] downscale)
        self.trained = 0
        self._hashes: dict[Path, str] = {}

    def candidates(self, scene: str, fit_key: str) -> list[Path]:
        if self.fit:
            return [self.out / "fits" / scene / f"{fit_key}.ply"]
        assert self.fits_dir is not None
        return [self.fits_dir / scene / f"{fit_key}.ply", self.fits_dir / scene / "fits" / f"{fit_key}.ply"]

    def existing(self, scene: str, fit_key: str) -> Path | None:
        return next((p for p in self.candidates(scene, fit_key) if p.is_file()), None)

    def config(self) -> FitConfig:
        """The configuration of every fit made here: ``fit_config``, else the standard schedule compressed to
        ``fit_iterations``."""
        if self.fit_config is not None:
            return self.fit_config
        if self.fit_iterations == DEFAULT_FIT_ITERATIONS:
            return FitConfig()
        return FitConfig.schedule(
            self.fit_iterations, densify_every=min(100, max(1, self.fit_iterations // 50))
        )

    def ensure(
        self,
        scene: Scene,
        fit_key: str,
        fit_frames: Sequence[Frame],
        *,
        stop_fraction: float | None = None,
        cycle: tuple[str, float] | None = None,
    ) -> None:
        """Train the fit if ``--fit`` and it does not exist yet.

        ``stop_fraction`` (the ``underfit`` recipe): run the schedule of the full fit but stop after
        ``max(1, round(stop_fraction × iterations))`` iterations.

        ``cycle = (base_key, shift_m)`` (the ``cycle`` recipe): the fit ``base_key`` (A, on ``fit_frames``) is
        made first when missing, then this fit is made on A's renders at the cameras of ``fit_frames``
        shifted ``shift_m`` metres sideways (:func:`~setdiff_bench.packets.cycle.cycle_views`; full masks),
        with the same configuration.
        """
        if not self.fit or self.existing(scene.name, fit_key) is not None:
            return

        target = self.candidates(scene.name, fit_key)[0]
        config = self.config()
        device = resolve_device(self.fit_device)
        if cycle is not None:
            self.ensure(scene, cycle[0], fit_frames)  # A first: the scene's own fit
        views = load_fit_views(scene, [f.name for f in fit_frames], downscale=self.downscale)
        if cycle is not None:
            base = read_ply(self(scene.name, cycle[0])[0])
            label = fit_key.rpartition("@")[2]
            views = cycle_views(base, views, cycle[1], config, label=label, device=device)
        stop = None if stop_fraction is None else max(1, round(stop_fraction * config.iterations))
        options = {} if stop is None else {"stop_after": stop}  # only then: full fits are called as before
        fit_views_to_ply(
            scene,
            views,
            config,
            target,
            device=device,
            checkpoint_dir=target.with_suffix(".ckpt"),
            checkpoint_every=1000,
            progress=self.progress,
            **options,
        )
        shutil.rmtree(target.with_suffix(".ckpt"), ignore_errors=True)
        self.trained += 1

    def __call__(self, scene: str, fit_key: str) -> tuple[Path, str]:
        path = self.existing(scene, fit_key)
        if path is None:
            expected = self.candidates(scene, fit_key)[0]
            raise DatasetError(
                f"missing 3DGS fit for scene {scene!r}, fit {fit_key!r} (expected this PLY, or "
                f"{self.candidates(scene, fit_key)[-1].name} under <scene>/fits/; or pass --fit)",
                expected,
            )
        if path not in self._hashes:
            self._hashes[path] = sha256_file(path)
        return path, self._hashes[path]


def gaussian_centres(source: FitSource) -> Callable[[str, str], np.ndarray]:
    """``(scene, fit key) -> (N, 3)`` float32 Gaussian centres of the fit (world frame), for trajectory bounds."""

    def centres(scene: str, fit_key: str) -> np.ndarray:
        path, _ = source(scene, fit_key)
        return read_ply(path).means.detach().cpu().numpy()

    return centres
