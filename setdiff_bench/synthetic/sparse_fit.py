"""Fitting a sparse-view scene's 3DGS models: ``fits/n{k}.ply`` on the views the 3DGS-Enhancer rule picks
for each of the preset's view counts (:func:`fit_sparse_scene`).
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from pathlib import Path

from setdiff_bench.synthetic.sparse_names import fit_views
from setdiff_bench.synthetic.sparse_preset import SparsePreset


def fit_sparse_scene(
    scene_dir: Path,
    preset: SparsePreset,
    *,
    device: str = "cpu",
    overwrite: bool = False,
    report: Callable[[str, int, int], None] | None = None,
) -> list[str]:
    """Fit ``fits/n{k}.ply`` for every ``k`` of ``preset.views`` on the 3DGS-Enhancer rule's views (the
    scene read through the DL3DV loader, cameras pinhole as the protocol says); returns one summary
    line per fit.  ``report(fit_key, iteration, iterations)`` receives progress."""
    from setdiff_bench.gaussians.fit import fit_scene

    lines = []
    iterations = preset.fit.iterations
    every = max(1, iterations // 100)
    for key, names in fit_views(preset).items():
        ply = scene_dir / "fits" / f"{key}.ply"
        if ply.is_file() and not overwrite:
            lines.append(f"{key} already present")
            continue
        checkpoint = ply.with_suffix(".checkpoint")
        if overwrite:
            shutil.rmtree(checkpoint, ignore_errors=True)

        def fitted(iteration: int, loss: float, key: str = key) -> None:
            del loss
            if report is not None and (iteration % every == 0 or iteration == iterations):
                report(key, iteration, iterations)

        t0 = time.perf_counter()
        result = fit_scene(
            scene_dir.parent,
            ply,
            preset.fit,
            frames=names,
            device=device,
            checkpoint_dir=checkpoint,
            checkpoint_every=max(1, iterations // 5),
            progress=False,
            dataset="dl3dv",
            scene_name=scene_dir.name,
            loader_options={"distortion": "ignore"},
            on_iteration=fitted,
        )
        shutil.rmtree(checkpoint, ignore_errors=True)
        lines.append(f"{key}: {len(result.model)} Gaussians in {time.perf_counter() - t0:.1f} s")
    return lines
