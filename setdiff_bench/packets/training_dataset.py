"""Training samples from a packet store: :class:`PacketTrainingDataset`, a torch ``Dataset`` of
:class:`~setdiff_bench.types.TrainingSample` (references, targets, their ground truth ``(M, 3, H, W)`` and
masks ``(M, 1, H, W)``) drawn with a variable set size and random order within roles."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import torch

from setdiff_bench.geometry import renormalize
from setdiff_bench.types import TrainingSample

if TYPE_CHECKING:
    from setdiff_bench.packets.store import PacketStore


class PacketTrainingDataset(torch.utils.data.Dataset):
    """Training samples drawn from stored packets: variable set size, random order within roles.

    Item ``index`` of epoch ``e`` (:meth:`set_epoch`) uses ``numpy.random.default_rng([seed, e, index])``:

    1. the set size is uniform in ``[min_views, max_views]`` (capped by the packet's view count);
    2. references and targets keep the packet's proportion (at least one target, and one reference
       when the packet has any);
    3. the chosen references and targets are each randomly permuted (the paper's permutation π);
    4. the subset is re-normalised so its own first target is the identity and its largest pairwise
       camera distance is 1 — the invariant every packet satisfies at inference.

    Only the chosen views' files are read.  ``Packet.scale`` composes both normalisations.
    """

    def __init__(
        self,
        store: PacketStore,
        packet_ids: Sequence[str],
        *,
        min_views: int = 8,
        max_views: int = 12,
        seed: int = 0,
    ) -> None:
        if not 2 <= min_views <= max_views:
            raise ValueError(f"need 2 <= min_views <= max_views, got {min_views}, {max_views}")
        self.store, self.packet_ids = store, list(packet_ids)
        self.min_views, self.max_views, self.seed, self.epoch = min_views, max_views, seed, 0

    def __len__(self) -> int:
        return len(self.packet_ids)

    def set_epoch(self, epoch: int) -> None:
        """Select the epoch whose random draws :meth:`__getitem__` makes."""
        self.epoch = int(epoch)

    def choose(self, index: int) -> tuple[list[int], list[int]]:
        """Reference and target positions of item ``index`` in the current epoch (rules in the class doc)."""
        rows = self.store.rows(self.packet_ids[index])
        n_ref, n_tgt = int((rows["role"] == "ref").sum()), int((rows["role"] == "target").sum())
        rng = np.random.default_rng([self.seed, self.epoch, index])
        total = n_ref + n_tgt
        size = int(rng.integers(min(self.min_views, total), min(self.max_views, total) + 1))
        refs = min(max(round(size * n_ref / total), 1 if n_ref else 0), n_ref, size - 1)
        targets = min(size - refs, n_tgt)
        refs = min(size - targets, n_ref)
        return (
            [int(i) for i in rng.permutation(n_ref)[:refs]],
            [int(i) for i in rng.permutation(n_tgt)[:targets]],
        )

    def __getitem__(self, index: int) -> TrainingSample:
        packet_id = self.packet_ids[index]
        ref_ids, tgt_ids = self.choose(index)
        packet = self.store.load_packet(packet_id, ref_ids, tgt_ids)
        gt, masks = self.store.load_ground_truth(packet_id, tgt_ids)
        packet = renormalize(packet)
        metadata = {
            **packet.metadata,
            "reference_positions": tuple(ref_ids),
            "target_positions": tuple(tgt_ids),
            "epoch": self.epoch,
        }
        packet = replace(packet, metadata=metadata)
        return TrainingSample(packet=packet, target_gt=gt, target_masks=masks)
