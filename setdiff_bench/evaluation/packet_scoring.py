"""Enhance and score one packet: the rules every run applies, in one place.

:func:`score_packet` is what ``setdiff-bench run`` does for each packet (``evaluation/run/`` calls it),
and what a notebook calls to try a method on one packet::

    import setdiff_bench as sb

    store = sb.PacketStore("runs/demo/work/packets")
    enhancer = sb.create_enhancer("setdiff", checkpoint="tiny_setdiff")
    print(sb.score_packet(enhancer, store, store.packet_ids("test")[0]).means())

The rules, in order:

1. the enhancer sees the packet without ground truth or masks (:meth:`PacketStore.load_packet`);
2. its output must be a finite float tensor ``(M, 3, H, W)`` — one image per target at the packet's
   size (:func:`check_output`, else :class:`EnhancerOutputError`);
3. it is rounded to the 8-bit grid, exactly as ``run`` writes it to PNG (:func:`~setdiff_bench.evaluation.
   scoring.quantize`), so a score never depends on precision a saved image does not have;
4. every image metric is computed against the ground truth with the dynamic-object masks applied;
   a target without ground truth (a novel-trajectory view, ``prepare --trajectory``) is enhanced and
   returned like any other, its paired metrics are NaN and named in :attr:`PacketScore.skipped`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import torch

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.evaluation.scoring import quantize, resolve_metrics, score_images
from setdiff_bench.metrics.registry import MetricSpec
from setdiff_bench.types import Packet, names_summary, tensor_summary

if TYPE_CHECKING:
    from setdiff_bench.enhancers.base import Enhancer
    from setdiff_bench.packets.store import PacketStore


class EnhancerOutputError(SetDiffBenchError):
    """An enhancer returned something other than ``(M, 3, H, W)`` finite images."""


@dataclass(frozen=True)
class PacketScore:
    """One packet, enhanced and scored.

    Attributes:
        packet_id: the packet's id in its store.
        enhanced: ``(M, 3, H, W)`` float32 on the CPU, on the 8-bit grid (what ``run`` writes as PNG).
        scores: metric name → ``(M,)`` float64, one value per target in stored order; NaN for a target
            without ground truth.
        elapsed_ms: the enhancer's wall time for the packet (``enhance()`` only; no I/O, no scoring).
        peak_memory_mb: on CUDA the most memory torch allocated during ``enhance()``; on the CPU the
            process's peak resident memory so far (MiB; the process peak includes the loaded model).
        has_ground_truth: ``(M,)`` bool, which targets were scored (``None``: all of them).
        skipped: the metrics not computed for some target because it has no ground truth (empty when
            every target has it).
        targets: the ``M`` target frame names in stored order (``scores``' order); :meth:`per_target` is the
            scores as a table indexed by them.
    """

    packet_id: str
    enhanced: torch.Tensor
    scores: dict[str, np.ndarray]
    elapsed_ms: float
    peak_memory_mb: float = float("nan")
    has_ground_truth: np.ndarray | None = None
    skipped: tuple[str, ...] = ()
    targets: tuple[str, ...] = ()

    def __repr__(self) -> str:
        means = ", ".join(f"{name} {value:.4g}" for name, value in self.means().items())
        return (
            f"PacketScore({self.packet_id!r}, {len(self.enhanced)} targets {names_summary(self.targets)}, "
            f"enhanced {tensor_summary(self.enhanced)}, means: {means or 'none'}, {self.elapsed_ms:.1f} ms)"
        )

    def per_target(self) -> pd.DataFrame:
        """The scores as a table: one row per target, indexed by its frame name (``target``), one float column
        per metric (NaN for a target without ground truth)."""
        names = list(self.targets) or [str(i) for i in range(len(self.enhanced))]
        index = pd.Index(names, name="target")
        return pd.DataFrame({name: np.asarray(values) for name, values in self.scores.items()}, index=index)

    @property
    def ms_per_frame(self) -> float:
        """``elapsed_ms`` divided by the number of targets (the ``ms_per_frame`` column of ``run``)."""
        return self.elapsed_ms / max(1, int(self.enhanced.shape[0]))

    def means(self) -> dict[str, float]:
        """Metric name → mean over the packet's targets that have ground truth (a metric no target could
        be scored on is left out: see :attr:`skipped`)."""
        keep = self.has_ground_truth
        if keep is None:
            return {name: float(np.mean(values)) for name, values in self.scores.items()}
        return {name: float(np.mean(values[keep])) for name, values in self.scores.items() if keep.any()}


def check_output(output: Any, packet: Packet, name: str) -> torch.Tensor:
    """``output`` as a detached float32 CPU tensor, after checking it is ``(M, 3, H, W)`` finite floats.

    Args:
        output: what ``enhancer.enhance(packet)`` returned.
        packet: the packet it was given (its targets and size decide the expected shape).
        name: the method's name, for the message.

    Raises:
        EnhancerOutputError: not a tensor, another shape, not floating point, or NaN / infinite values.
    """
    where = f"method {name}, packet {packet.packet_id}"
    expected = (len(packet.targets), 3, packet.height, packet.width)
    if not isinstance(output, torch.Tensor):
        raise EnhancerOutputError(
            f"enhance() returned {type(output).__name__}, expected a tensor {expected}", where
        )
    if tuple(output.shape) != expected:
        raise EnhancerOutputError(
            f"enhance() returned shape {tuple(output.shape)}, expected {expected}", where
        )
    if not output.is_floating_point():
        raise EnhancerOutputError(f"enhance() returned dtype {output.dtype}, expected float in [0, 1]", where)
    if not torch.isfinite(output).all():
        raise EnhancerOutputError("enhance() returned NaN or infinite values", where)
    return output.detach().float().cpu()


def score_packet(
    enhancer: Enhancer,
    store: PacketStore | str | os.PathLike[str],
    packet_id: str,
    *,
    metrics: str | Sequence[str] | Sequence[MetricSpec] = "standard",
    device: str | torch.device | None = None,
    batch_size: int = 8,
) -> PacketScore:
    """Enhance one packet of a store and score it against its ground truth.

    Args:
        enhancer: a built method (:func:`setdiff_bench.create_enhancer`, or any object with ``name`` and
            ``enhance(packet) -> (M, 3, H, W)``).
        store: a :class:`~setdiff_bench.packets.store.PacketStore` or its folder.
        packet_id: one of ``store.packet_ids()``.
        metrics: a preset (``"standard"``: PSNR, SSIM, LPIPS-alex), a comma list or sequence of metric
            names, or metric specs.
        device: where the metrics run (default: the enhancer's own ``device`` if it has one, else the CPU).
        batch_size: images per metric call (bounds LPIPS memory; does not change the values).

    Returns:
        The 8-bit enhanced images, per-target scores and the enhancer's time.  Targets without ground
        truth (novel-trajectory packets) are enhanced and get NaN scores; the metrics so skipped are
        named in ``skipped``.

    Raises:
        SetDiffBenchError: an unknown packet or metric (named as the ``packet_id`` / ``metrics``
            parameter), an unreadable packet file, or an output of the wrong shape
            (:class:`EnhancerOutputError`).
    """
    from setdiff_bench.errors import UsageError
    from setdiff_bench.packets.store import PacketStore

    if batch_size < 1:
        raise UsageError(f"batch_size must be >= 1, got {batch_size}", "batch_size")
    if isinstance(store, (str, os.PathLike)):
        store = PacketStore(store)
    try:
        store.rows(packet_id)
    except SetDiffBenchError:
        raise UsageError(
            f"no packet {packet_id!r} in the store at {store.root} (store.packet_ids() lists them)",
            "packet_id",
        ) from None
    specs = _specs(metrics)
    target_device = torch.device(device if device is not None else getattr(enhancer, "device", None) or "cpu")
    packet = store.load_packet(packet_id)
    has_gt = np.asarray(store.has_ground_truth(packet_id), dtype=bool)
    scored = np.flatnonzero(has_gt)
    gt, masks = (
        store.load_ground_truth(packet_id)
        if has_gt.all()
        else store.load_ground_truth(packet_id, targets=[int(i) for i in scored])
        if len(scored)
        else (None, None)
    )
    if target_device.type == "cuda":
        torch.cuda.synchronize(target_device)
        torch.cuda.reset_peak_memory_stats(target_device)
    start = time.perf_counter()
    output = enhancer.enhance(packet)
    if isinstance(output, torch.Tensor) and output.is_cuda:
        torch.cuda.synchronize(output.device)
    elapsed_ms = (time.perf_counter() - start) * 1000.0
    peak_memory_mb = peak_memory_bytes(target_device) / (1 << 20)
    enhanced = quantize(check_output(output, packet, enhancer.name))
    if has_gt.all():
        assert gt is not None and masks is not None
        scores = score_images(
            specs, enhanced.to(target_device), gt.to(target_device), masks.to(target_device), batch_size
        )
        return PacketScore(
            packet_id, enhanced, scores, elapsed_ms, peak_memory_mb, targets=packet.targets.names
        )
    scores = {spec.name: np.full(len(has_gt), np.nan) for spec in specs}
    if gt is not None and masks is not None:
        paired = score_images(
            specs,
            enhanced[scored].to(target_device),
            gt.to(target_device),
            masks.to(target_device),
            batch_size,
        )
        for name, values in paired.items():
            scores[name][scored] = values
    skipped = tuple(spec.name for spec in specs)
    return PacketScore(
        packet_id, enhanced, scores, elapsed_ms, peak_memory_mb, has_gt, skipped, targets=packet.targets.names
    )


def peak_memory_bytes(device: torch.device) -> int:
    """CUDA: the most memory torch allocated on ``device`` since its peak was last reset; CPU: this
    process's peak resident set size (``ru_maxrss``, KiB on Linux)."""
    if device.type == "cuda":
        return int(torch.cuda.max_memory_allocated(device))
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def _specs(metrics: str | Sequence[str] | Sequence[MetricSpec]) -> tuple[MetricSpec, ...]:
    if not isinstance(metrics, str) and metrics and all(isinstance(m, MetricSpec) for m in metrics):
        return tuple(metrics)  # type: ignore[arg-type]
    return resolve_metrics(metrics, option="metrics")  # type: ignore[arg-type]
