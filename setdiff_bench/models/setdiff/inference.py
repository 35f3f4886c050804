"""Enhance a whole :class:`~setdiff_bench.types.Packet` with a :class:`SetDiffModel`.

SetDiff: all (up to ``max_references``) references and all targets form one set (or sets of
``targets_per_set`` targets, each with every reference).  DiFix: the packet's first reference — the
packet builder orders references best first by Eq. 2 — plus one target per set; the M sets share the
same layout and are stacked on the batch axis (sets never attend to each other, so this equals
running them one at a time).
"""

from __future__ import annotations

import torch

from setdiff_bench.models.setdiff.inputs import check_packet, target_sets, view_tensors
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.types import Packet


@torch.no_grad()
def enhance_packet(model: SetDiffModel, packet: Packet, *, guidance_scale: float | None = None,
                   sets_per_call: int | None = None, max_references: int | None = None,
                   targets_per_set: int | None = None) -> torch.Tensor:
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
    images, geometry, num_refs = view_tensors(packet, use_geometry=config.use_geometry, cmap_clip=config.cmap_clip,
                                              max_references=config.max_references if max_references is None
                                              else max_references,
                                              geometry_inputs=config.geometry_inputs)
    output = torch.empty((len(packet.targets), 3, packet.height, packet.width), dtype=torch.float32)
    per_set_targets = config.targets_per_set if targets_per_set is None else targets_per_set
    for batch, target_ids in target_sets(images, geometry, num_refs, per_set_targets):
        step = batch.num_sets if sets_per_call is None else max(1, sets_per_call)
        per_set = batch.num_targets
        for start in range(0, batch.num_sets, step):
            stop = min(start + step, batch.num_sets)
            part = type(batch)(batch.images[start:stop],
                               None if batch.geometry is None else batch.geometry[start:stop], num_refs)
            enhanced = model.enhance(part.to(parameter.device, parameter.dtype), guidance_scale=guidance_scale)
            ids = target_ids[start * per_set: stop * per_set]
            output[ids] = enhanced.reshape(-1, *enhanced.shape[2:]).float().cpu()
    return output
