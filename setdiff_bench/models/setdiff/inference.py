"""Enhance a whole :class:`~setdiff_bench.types.Packet` with a :class:`SetDiffModel`.

SetDiff: all (up to ``max_references``) references and all targets form one set (or sets of
``targets_per_set`` targets, each with every reference).  DiFix: the packet's first reference — the
packet builder orders references best first by Eq. 2 — plus one target per set; the M sets share the
same layout and are stacked on the batch axis (sets never attend to each other, so this equals
running them one at a time).

A set that is a proper subset of the packet (fewer references, or targets split into several sets)
is re-normalised into its own first target's frame with unit camera extent before its geometry is
built — exactly as training normalises every drawn subset (:func:`.inputs.renormalize`) — so the
set-size ablation feeds each subset the geometry statistics the model was trained on.  The whole
packet already satisfies that invariant and is used as it is.
"""

from __future__ import annotations

from dataclasses import replace

import torch

from setdiff_bench.geometry import renormalize
from setdiff_bench.models.setdiff.inputs import SetBatch, check_packet, surface_points, view_tensors
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.types import Packet


def target_chunks(num_targets: int, targets_per_set: int | None) -> list[list[int]]:
    """Target indices split into consecutive sets of ``targets_per_set`` (``None`` = one set)."""
    size = num_targets if targets_per_set is None else max(1, min(targets_per_set, num_targets))
    return [list(range(start, min(start + size, num_targets))) for start in range(0, num_targets, size)]


def stacked(tensors: list[torch.Tensor]) -> torch.Tensor:
    """``torch.stack`` on a new first axis, without a copy for a single tensor (one set per call)."""
    return tensors[0].unsqueeze(0) if len(tensors) == 1 else torch.stack(tensors)


def set_packets(
    packet: Packet, max_references: int | None, targets_per_set: int | None, *, renormalise: bool
) -> list[tuple[Packet, list[int]]]:
    """The sets a packet is enhanced in: ``(set packet, indices of its targets in the packet)``.

    Each set holds the first ``max_references`` references (best first by Eq. 2) and one chunk of
    targets.  With ``renormalise`` every set that is not the whole packet is moved into its first
    target's frame (:func:`.inputs.renormalize`), as training does for each drawn subset.
    """
    references = packet.references
    if max_references is not None and len(references) > max_references:
        references = references.subset(range(max_references))
    chunks = target_chunks(len(packet.targets), targets_per_set)
    whole = len(references) == len(packet.references) and len(chunks) == 1
    sets = []
    for chunk in chunks:
        subset = (
            packet if whole else replace(packet, references=references, targets=packet.targets.subset(chunk))
        )
        if renormalise and not whole:
            subset = renormalize(subset)
        sets.append((subset, chunk))
    return sets


@torch.no_grad()
def enhance_packet(
    model: SetDiffModel,
    packet: Packet,
    *,
    guidance_scale: float | None = None,
    sets_per_call: int | None = None,
    max_references: int | None = None,
    targets_per_set: int | None = None,
) -> torch.Tensor:
    """The packet's M targets enhanced, ``(M, 3, H, W)`` float32 in [0, 1] on the CPU, packet order.

    Args:
        model: the model (its device and dtype are used for the computation).
        packet: N ≥ 0 references and M ≥ 1 targets; H and W divisible by 8.
        guidance_scale: geometry CFG scale (default: the model config's).
        sets_per_call: at most this many sets per UNet call (memory bound); ``None`` = all.
        max_references, targets_per_set: override the config's set sizes (N = the first
            ``max_references`` references, best first by Eq. 2; targets enhanced ``targets_per_set`` at a
            time, each set with all N references) — the set-size ablation (paper Table 6).

    Raises:
        PacketError: no targets, mixed sizes, or a size not divisible by the latent factor.
    """
    config = model.config
    check_packet(packet, config.latent_factor)
    parameter = next(model.parameters())
    references = config.max_references if max_references is None else max_references
    per_set = config.targets_per_set if targets_per_set is None else targets_per_set
    sets = set_packets(packet, references, per_set, renormalise=config.use_geometry)
    # Sets of the same size share one stacked batch (sets never attend to each other).
    by_size: dict[int, list[tuple[Packet, list[int]]]] = {}
    for subset, chunk in sets:
        by_size.setdefault(len(chunk), []).append((subset, chunk))
    output = torch.empty((len(packet.targets), 3, packet.height, packet.width), dtype=torch.float32)
    for group in by_size.values():
        step = len(group) if sets_per_call is None else max(1, sets_per_call)
        for start in range(0, len(group), step):
            part = group[start : start + step]
            tensors = [
                view_tensors(
                    subset,
                    use_geometry=config.use_geometry,
                    cmap_clip=config.cmap_clip,
                    geometry_inputs=config.geometry_inputs,
                )
                for subset, _ in part
            ]
            num_refs = tensors[0][2]
            geometry = None if tensors[0][1] is None else stacked([g for _, g, _ in tensors])
            points = (
                stacked([surface_points(subset, snapped=config.snapped_points) for subset, _ in part])
                if config.needs_points
                else None
            )
            batch = SetBatch(stacked([images for images, _, _ in tensors]), geometry, num_refs, points)
            del tensors, geometry, points  # the batch holds them now (at 576×1024: GBs for a large set)
            enhanced = model.enhance(
                batch.to(parameter.device, parameter.dtype), guidance_scale=guidance_scale
            )
            ids = [t for _, chunk in part for t in chunk]
            output[ids] = enhanced.reshape(-1, *enhanced.shape[2:]).float().cpu()
    return output
