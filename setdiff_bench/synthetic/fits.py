"""How a synthetic scene kind fits its 3DGS models, declared as data (:class:`FitRecipe`), and what every
kind does around fitting one model (:meth:`FitRecipe.fit`): keep a fit whose PLY is present unless
``overwrite``, resume an interrupted fit from its checkpoint and remove the checkpoint once the PLY is
written, report progress about every 1 % and time the fit.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, Protocol, TypeVar

from setdiff_bench.gaussians.fit import FitConfig

#: ``report(fit key, iteration, iterations)``: a fit's progress.
FitReport = Callable[[str, int, int], None]


class FittedPreset(Protocol):
    """A preset: all :meth:`FitRecipe.fit` reads of it is its fit configuration."""

    @property
    def fit(self) -> FitConfig: ...


Preset = TypeVar("Preset", bound=FittedPreset)


@dataclass(frozen=True)
class FitRecipe(Generic[Preset]):
    """The 3DGS fits of one scene kind: ``<scene>/fits/<key>.ply`` for each key, with ``preset.fit``.

    Attributes:
        keys: ``(preset) -> fit keys``, in the order they are fitted.
        source: ``(scene_dir, preset, key) ->`` the keyword arguments of
            :func:`setdiff_bench.gaussians.fit.fit_scene` that say what the fit is fitted on (``scene_dir``,
            and ``frames``, ``dataset``, ``scene_name``, ``loader_options`` as needed).
        present: the summary line of a fit kept (``str.format`` field ``key``).
        fitted: the summary line of a fit made (fields ``key``, ``gaussians`` and ``seconds``).
    """

    keys: Callable[[Preset], tuple[str, ...]]
    source: Callable[[Path, Preset, str], Mapping[str, Any]]
    present: str
    fitted: str

    def fit(
        self,
        scene_dir: Path,
        preset: Preset,
        *,
        device: str = "cpu",
        overwrite: bool = False,
        report: FitReport | None = None,
    ) -> list[str]:
        """Fit the scene's models on ``device``, each kept if its PLY is present unless ``overwrite``;
        returns one summary line per fit.  ``report(key, iteration, iterations)`` receives progress."""
        from setdiff_bench.gaussians.fit import fit_scene

        lines = []
        iterations = preset.fit.iterations
        every = max(1, iterations // 100)
        for key in self.keys(preset):
            ply = scene_dir / "fits" / f"{key}.ply"
            if ply.is_file() and not overwrite:
                lines.append(self.present.format(key=key))
                continue
            checkpoint = ply.with_suffix(".checkpoint")
            if overwrite:
                shutil.rmtree(checkpoint, ignore_errors=True)

            def on_iteration(iteration: int, loss: float, key: str = key) -> None:
                del loss
                if report is not None and (iteration % every == 0 or iteration == iterations):
                    report(key, iteration, iterations)

            t0 = time.perf_counter()
            result = fit_scene(
                out_ply=ply,
                config=preset.fit,
                device=device,
                checkpoint_dir=checkpoint,
                checkpoint_every=max(1, iterations // 5),
                progress=False,
                on_iteration=on_iteration,
                **self.source(scene_dir, preset, key),
            )
            shutil.rmtree(checkpoint, ignore_errors=True)
            seconds = time.perf_counter() - t0
            lines.append(self.fitted.format(key=key, gaussians=len(result.model), seconds=seconds))
        return lines
