"""The training samples one process of a (possibly distributed) training run draws, resumable:
:class:`SampleStream` (used by :func:`setdiff_bench.models.setdiff.train.train`)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import Any

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.types import TrainingSample


class SampleStream:
    """An endless, resumable stream of training samples for one process of a (possibly distributed) run.

    Map-style datasets (``__len__`` + ``__getitem__``): the *global* sample sequence is the concatenation
    of seeded per-epoch permutations (epoch ``e`` shuffled with ``seed * 1_000_003 + e``); global position
    ``g`` is consumed by rank ``g % world``.  So the ranks of one optimiser step draw disjoint samples, their
    union is what a single process with ``world``-fold gradient accumulation draws, a dataset smaller than
    the world still gives every rank a different sample, and ``start`` (a global position) resumes the
    sequence where it stopped, even with another number of processes.  Other iterables are cycled in their
    own order, element ``k`` going to rank ``k % world`` (and restart from the beginning on resume).

    After each ``next()``, :attr:`last` holds ``(global position, dataset index)`` of the sample returned
    (``None`` as the index for iterables).

    With ``sparsest_share`` p > 0 and the dataset's ``reference_counts``, an epoch is no longer a permutation:
    each of its ``len(dataset)`` slots comes, with probability p, from the packets with the fewest
    references (e.g. the n3 packets) and otherwise from the rest, each group visited in its own seeded
    shuffle, cycled (:meth:`epoch_permutation`); still a function of ``seed`` and the epoch alone, so
    resuming works as before.
    """

    def __init__(
        self,
        dataset: Sequence[TrainingSample] | Iterable[TrainingSample],
        *,
        seed: int,
        rank: int = 0,
        world: int = 1,
        start: int = 0,
        num_workers: int = 0,
        sparsest_share: float = 0.0,
        reference_counts: Sequence[int] | None = None,
    ) -> None:
        if not 0 <= rank < world:
            raise ValueError(f"rank {rank} outside a world of {world}")
        if not 0.0 <= sparsest_share < 1.0:
            raise ValueError(f"sparsest_share must be in [0, 1), got {sparsest_share}")
        self.sparsest_share = float(sparsest_share)
        self.reference_counts = None if reference_counts is None else [int(c) for c in reference_counts]
        self.dataset, self.seed, self.rank, self.world = dataset, seed, rank, world
        self.start, self.num_workers = start, num_workers
        self.last: tuple[int, int | None] | None = None
        self.map_style = hasattr(dataset, "__len__") and hasattr(dataset, "__getitem__")
        if self.map_style and len(dataset) == 0:  # type: ignore[arg-type]
            raise UsageError("the training dataset is empty", "--packets")
        self._iterator = self._map_style() if self.map_style else self._cycle()

    def __iter__(self) -> Iterator[TrainingSample]:
        return self

    def __next__(self) -> TrainingSample:
        return next(self._iterator)

    def epoch_permutation(self, epoch: int) -> list[int]:
        """Dataset indices in the order the global sequence visits them during ``epoch`` (a permutation, or
        with ``sparsest_share`` the weighted draw of the class doc)."""
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + epoch)
        size = len(self.dataset)  # type: ignore[arg-type]
        counts = self.reference_counts
        if self.sparsest_share <= 0 or counts is None:
            return torch.randperm(size, generator=generator).tolist()
        if len(counts) != size:
            raise ValueError(f"{len(counts)} reference counts for a dataset of {size}")
        fewest = min(counts)
        sparse = [i for i, c in enumerate(counts) if c == fewest]
        rest = [i for i, c in enumerate(counts) if c != fewest]
        if not rest:
            return torch.randperm(size, generator=generator).tolist()
        groups = [
            [group[j] for j in torch.randperm(len(group), generator=generator).tolist()]
            for group in (sparse, rest)
        ]
        picks = (torch.rand(size, generator=generator) < self.sparsest_share).tolist()
        taken = [0, 0]
        order = []
        for pick_sparse in picks:
            which = 0 if pick_sparse else 1
            order.append(groups[which][taken[which] % len(groups[which])])
            taken[which] += 1
        return order

    def _map_style(self) -> Iterator[TrainingSample]:
        size = len(self.dataset)  # type: ignore[arg-type]
        # the first global position at or after ``start`` that belongs to this rank
        position = self.start + (self.rank - self.start) % self.world
        while True:
            epoch = position // size
            if hasattr(self.dataset, "set_epoch"):  # e.g. the packet store's dataset: new draws per epoch
                self.dataset.set_epoch(epoch)
            permutation = self.epoch_permutation(epoch)
            positions = range(position, (epoch + 1) * size, self.world)
            indices = [permutation[g - epoch * size] for g in positions]
            if self.num_workers > 0:
                loader = torch.utils.data.DataLoader(
                    self.dataset,
                    batch_size=None,
                    sampler=indices,  # type: ignore[arg-type]
                    num_workers=self.num_workers,
                    collate_fn=_identity,
                )
                samples: Iterable[TrainingSample] = loader
            else:
                samples = (self.dataset[index] for index in indices)  # type: ignore[index]
            for g, index, sample in zip(positions, indices, samples, strict=True):
                self.last = (g, index)
                yield sample
            position = (
                positions[-1] + self.world
            )  # ``positions`` is never empty: position < (epoch + 1) * size

    def _cycle(self) -> Iterator[TrainingSample]:
        while True:
            empty = True
            for number, sample in enumerate(self.dataset):
                if number % self.world == self.rank:
                    empty = False
                    self.last = (number, None)
                    yield sample
            if empty:
                raise UsageError("the training dataset yielded no samples for this process", "--packets")


def dataset_reference_counts(dataset: Sequence[TrainingSample] | Iterable[TrainingSample]) -> list[int]:
    """The number of references of every packet of a map-style dataset: read from the packet store's index
    for a store dataset (``dataset.store`` and ``dataset.packet_ids``, nothing loaded), else from the samples.

    Raises:
        UsageError: the dataset is not map-style (an iterable has no index to weight).
    """
    store, ids = getattr(dataset, "store", None), getattr(dataset, "packet_ids", None)
    if store is not None and ids is not None:
        return [int((store.rows(pid)["role"] == "ref").sum()) for pid in ids]
    if not (hasattr(dataset, "__len__") and hasattr(dataset, "__getitem__")):
        raise UsageError("sparsest_share needs a map-style dataset (a packet store or a list)", "[train]")
    return [len(dataset[i].packet.references) for i in range(len(dataset))]  # type: ignore[index,arg-type]


def _identity(sample: Any) -> Any:
    return sample
