"""What a ``prepare`` call is asked to do: every option of :func:`setdiff_bench.packets.prepare.prepare`
(and of ``setdiff-bench prepare``) but the dataset, its root and the store, declared once.

``prepare(dataset, root, out, fit=True, split="test")`` is ``prepare(dataset, root, out,
PrepareSettings(fit=True, split="test"))``; the CLI builds the settings from its flags.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from setdiff_bench.gaussians.fit import FitConfig
from setdiff_bench.packets.fits import DEFAULT_FIT_ITERATIONS
from setdiff_bench.packets.shards import Shard

#: ``split``'s values: the protocol's train or test scenes, or every scene.
SPLIT_CHOICES = ("train", "test", "all")
#: How C-map EXRs are stored: exact ``float32`` or ``half`` (about 3.5x smaller files).
CmapPrecision = Literal["float32", "half"]


@dataclass(frozen=True)
class PrepareSettings:
    """The options of one ``prepare`` call (see :mod:`setdiff_bench.packets.prepare` for what they do).

    Attributes:
        protocol: packaged protocol name or TOML path; default: the dataset's own.
        fits, fit: user PLYs folder, or fit here (exactly one; :mod:`setdiff_bench.packets.fits`).
        split: ``train``, ``test`` or ``all`` scenes (the protocol's scene split; :data:`SPLIT_CHOICES`).
        scenes: restrict to these scene names (the split is still computed over all scenes).
        workers: render processes.  shard: which units this call prepares.
        backend, device: renderer (``auto``/``torch``/``gsplat``) and torch device (``auto``/``cpu``/``cuda``).
        loader_options: override the protocol's ``[loader]`` options.
        fit_iterations: 3DGS iterations with ``fit`` (the standard schedule compressed to them; default
            :data:`~setdiff_bench.packets.fits.DEFAULT_FIT_ITERATIONS`, ``FitConfig.iterations``).
        fit_config: the whole 3DGS configuration with ``fit``, in place of ``fit_iterations`` (e.g. the fit
            of a synthetic preset, so that degraded recipe fits differ from the scene's own fit only as the
            recipe says).
        threads: torch intra-op threads per render process (default 1: the tile rasteriser's ops are
            small, and on a busy machine extra threads slowed a 48×32 render 50× (measured); use
            ``workers`` for parallelism, or more threads for large CPU renders).
        cmap_precision: ``"float32"`` (default) or ``"half"`` C-map EXRs (see :mod:`setdiff_bench.packets.store`).
        progress: show tqdm bars.
        groups: only these protocol groups (default all), e.g. ``["holdout8"]`` of a generic capture.
        test_scenes: these scenes are the test scenes and every other one trains, in place of the
            protocol's split rule (:func:`~setdiff_bench.packets.prepare.declared_split`).
        trajectories: novel-trajectory specs (``shift:N``, ``yaw:D``, a pose ``.json``;
            :mod:`setdiff_bench.packets.trajectory`): instead of the protocol's groups, write per spec and
            fit the packets whose targets are the fit frames' cameras moved along it, rendered with
            C-maps and without ground truth, references chosen by Eq. 2 among the fit frames
            (:func:`~setdiff_bench.packets.plan.plan_trajectories`; group ``shift+3m``, split ``test``).
            A spec that does not parse, a pose file for several scenes, or a camera leaving the scene
            bounds is refused before anything is written.
        pairs: training-pair recipes (``["sparse:4,underfit:0.5,cross-camera"]``;
            :mod:`setdiff_bench.packets.recipes`): instead of the protocol's groups, write per recipe and
            fit the packets whose targets are recorded frames with their ground truth, rendered from a 3DGS
            degraded as the recipe says (fit key ``<fit_key>@<label>``, trained here with ``fit``), with
            references chosen by Eq. 2 among the recorded frames it saw (group ``sparse4``, the scene's
            split).  An unknown recipe, a parameter out of range, or a recipe a scene cannot follow
            (``cross-camera`` on one camera) is refused before anything is written.
    """

    protocol: str | os.PathLike[str] | None = None
    fits: str | os.PathLike[str] | None = None
    fit: bool = False
    split: str = "all"
    scenes: Sequence[str] | None = None
    workers: int = 1
    shard: Shard = Shard()
    backend: str = "auto"
    device: str = "auto"
    loader_options: Mapping[str, Any] | None = None
    fit_iterations: int = DEFAULT_FIT_ITERATIONS
    fit_config: FitConfig | None = None
    threads: int = 1
    cmap_precision: CmapPrecision = "float32"
    progress: bool = True
    groups: Sequence[str] | None = None
    test_scenes: Sequence[str] | None = None
    trajectories: Sequence[str] | None = None
    pairs: Sequence[str] | None = None

    @property
    def cmap_half(self) -> bool:
        """Whether C-maps are stored as half floats (``cmap_precision="half"``)."""
        return self.cmap_precision == "half"
