"""The run contract: the settings that decide a run's results, recorded in ``run.json``.

A resumed run, or another shard of the same run, must have the same :meth:`RunSettings.identity`;
:func:`jsonable_options` is how options and metric arguments are written into ``run.json``,
``enhancer.json`` and ``manifest.json``.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.jsonable import jsonable
from setdiff_bench.io.refit_layout import refit_cost
from setdiff_bench.metrics.registry import PRESETS

RUN_FORMAT = "setdiff-run/1"
#: Protocols whose targets are time-ordered camera sequences: warp error with ``warp="auto"``.  A
#: novel-trajectory packet (``prepare --trajectory shift:N | yaw:D``) keeps its protocol and the timestamps
#: of the fit frames it moves, so the trajectories of these protocols get warp error under ``auto`` too
#: (flow from the renders); other protocols' trajectories need ``warp="on"``.
SEQUENCE_PROTOCOLS = frozenset({"nuscenes"})
#: Columns that are measurements of time, not results: excluded from byte-identity comparisons.

WarpMode = Literal["auto", "on", "off"]
#: What a run's display name (:attr:`RunSettings.name`) may be: a letter or digit, then letters, digits and
#: ``_ . + -``, at most 64 characters (it names the default run folder and every table row).
RUN_NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,63}")


@dataclass(frozen=True)
class RunSettings:
    """Everything that decides a run's results (recorded in ``run.json``; a resume must match).

    Attributes:
        method: registry name (``setdiff-bench list methods``).
        options: factory options given by the user (``checkpoint``, ``source`` for ``--from``, plugin options).
        split: ``"train"``/``"test"`` or ``None`` for every packet.
        metrics: image metric names (default: the ``standard`` preset: PSNR, SSIM, LPIPS-alex).
        warp: warp error per sequence: ``auto`` (on for :data:`SEQUENCE_PROTOCOLS`, their novel-trajectory
            packets included), ``on`` or ``off``.  Targets with ground truth take the flow from it; targets
            without (novel trajectories) from their 3DGS renders (:mod:`setdiff_bench.evaluation.run._sequences`).
        flow_method: optical flow for warp error (``deepflow`` or ``dis``).
        device: where the enhancer (if it takes ``device``) and the metrics run.
        batch_size: images per metric call (bounds LPIPS memory); does not change results.
        warp_cache: folder caching the flow per sequence (shared by every method; keyed by the SHA-256 of
            the ground-truth files, or of the render files under a key of their own, and the flow method);
            ``"auto"`` = the user cache
            (:func:`setdiff_bench.evaluation.scoring.default_warp_cache`), ``None`` = no cache.  Does not change results.
        name: the run's display name (``run --name``), or ``None`` for the method's registry name.  It is what
            the ``method`` column of ``metrics.parquet`` / ``sequences.parquet`` holds, so the leaderboard,
            ``compare`` and the report show it; two runs of one method (e.g. two ``precomputed`` folders of two
            external methods) with different names share one table.  Recorded in ``run.json`` (when given)
            and in the manifest beside the registry name; :data:`RUN_NAME_PATTERN`.
        refit: the ``setdiff-bench refit --out`` folder whose refitted fits the packets were cut from (an
            ``X 3D`` run), or ``None``.  Each scene's refit manifest must be there; what it cost (time, peak
            memory) goes into the run's manifest and ``leaderboard --cost``, its SHA-256 into ``run.json``.
    """

    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    split: str | None = "test"
    metrics: tuple[str, ...] = PRESETS["standard"]
    warp: WarpMode = "auto"
    flow_method: str = "deepflow"
    device: str = "cpu"
    batch_size: int = 8
    warp_cache: str | None = "auto"
    name: str | None = None
    refit: str | None = None

    @property
    def label(self) -> str:
        """The name the run's rows carry: :attr:`name` when given, else :attr:`method`."""
        return self.name if self.name is not None else self.method

    def identity(
        self,
        index_sha256: str,
        model_files: Mapping[str, str] | None = None,
        refit_manifests: Mapping[str, str] | None = None,
    ) -> dict[str, Any]:
        """The ``run.json`` content: what must not change between a run and its resumption.

        ``model_files`` (``{file: SHA-256}`` from the method's fingerprint, e.g. a checkpoint's weights and
        config) is recorded when the method has one, so that the same ``--checkpoint`` naming other weights
        (retrained, re-exported, a newer shipped model) does not resume into stale results.
        ``refit_manifests`` (``{"<scene>/<fit_key>": SHA-256}`` of the refit manifests, with :attr:`refit`)
        likewise ties the run to the refits whose cost it records.
        """
        identity = {
            "format": RUN_FORMAT,
            "method": self.method,
            "options": jsonable_options(dict(self.options)),
            "split": self.split,
            "metrics": list(self.metrics),
            "warp": self.warp,
            "flow_method": self.flow_method,
            "device": self.device,
            "index_sha256": index_sha256,
        }
        if self.name is not None:  # absent when not given: runs made before names existed still resume
            identity["name"] = self.name
        if model_files:
            identity["model_files"] = dict(sorted(model_files.items()))
        if self.refit is not None:  # absent when not given: every other run's run.json is unchanged
            identity["refit_manifests"] = dict(sorted((refit_manifests or {}).items()))
        return identity


def refit_costs(
    settings: RunSettings, index: pd.DataFrame, packet_ids: Collection[str]
) -> dict[str, dict[str, Any]]:
    """``{"<scene>/<fit_key>": cost}`` of every scene and fit of the packets ``packet_ids`` in the store's
    ``index``, read from :attr:`RunSettings.refit` (:func:`setdiff_bench.io.refit_layout.refit_cost`); ``{}``
    without it.

    Raises:
        UsageError: a refit manifest missing or unreadable (the message names the file).
    """
    if settings.refit is None:
        return {}
    rows = index[index["packet_id"].isin(set(packet_ids))]
    fits = sorted({(str(scene), str(fit_key)) for scene, fit_key in zip(rows["scene"], rows["fit_key"])})
    return {f"{scene}/{fit_key}": refit_cost(settings.refit, scene, fit_key) for scene, fit_key in fits}


def check_run_name(settings: RunSettings, registered: Collection[str]) -> None:
    """Refuse a display name that is not :data:`RUN_NAME_PATTERN`, or that is another registered method's name
    (a ``precomputed`` run called ``setdiff`` would pass for the real one in every table).

    Raises:
        UsageError: naming the ``name`` parameter (the CLI's ``--name``).
    """
    name = settings.name
    if name is None:
        return
    if not RUN_NAME_PATTERN.fullmatch(name):
        raise UsageError(
            "a run's name is a letter or digit followed by letters, digits, '_', '.', '+' or '-' "
            "(at most 64 characters)",
            name,
            parameter="name",
        )
    if name != settings.method and name in registered:
        raise UsageError(
            f"{name!r} is the name of another method; choose a name no registered method has",
            name,
            parameter="name",
        )


def warp_enabled(settings: RunSettings, protocols: Sequence[str]) -> bool:
    """Whether warp error is computed for a run over ``protocols``."""
    if settings.warp == "auto":
        return any(protocol in SEQUENCE_PROTOCOLS for protocol in protocols)
    return settings.warp == "on"


def jsonable_options(value: Any) -> Any:
    """Options as JSON values: :func:`setdiff_bench.io.jsonable.jsonable` with leaves made JSON-safe (a
    non-finite float and any object that is not a bool, int, str or ``None`` become strings, e.g. paths;
    dataclasses are expanded)."""
    return jsonable(value, _option_leaf)


def _option_leaf(value: Any) -> Any:
    """One leaf of :func:`jsonable_options`."""
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if np.isfinite(value) else str(value)
    if hasattr(value, "__dataclass_fields__"):
        return jsonable_options(asdict(value))
    return str(value)
