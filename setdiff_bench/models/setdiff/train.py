"""Training loop for SetDiff and DiFix (same code; the config's ``method`` picks the set layout).

One micro-batch is one training set drawn from one :class:`~setdiff_bench.types.TrainingSample`:
a random subset of 8–12 of its views (references and targets in the packet's proportion, randomly
permuted; DiFix: one random target and its best reference by Eq. 2).  Per set, with probability
``geometry_dropout`` the C-maps and poses are removed together (geometry CFG).  The loss is the latent
loss on every target plus the reconstruction loss on ``decode_targets`` random decoded targets (see
:mod:`.losses`).  AdamW on the trainable parameters (UNet fully, Ψ, decoder LoRA or decoder, skip
convs, a learned text embedding), gradient clipping, gradient accumulation.

Runs under ``accelerate``: one process per GPU with DDP (``accelerate launch -m setdiff_bench.cli.main
train ...``; on CPUs ``accelerate launch --multi_gpu --num_processes N`` runs DDP over gloo), bf16 autocast
on CUDA and float32 on the CPU by default; total batch = processes × ``gradient_accumulation``.  The
samples form one global sequence (see :class:`SampleStream`); sample ``g`` goes to process ``g % world``
and every random choice of its set derives from ``seed`` and ``g`` alone.  So N processes train exactly
what one process with N-fold gradient accumulation trains (up to float summation order), and a resumed
run, with any number of processes, draws what an uninterrupted one would (for map-style datasets).
Validation samples are split across the processes and their scores reduced.  Only the main process
writes files.

Checkpoints are written every ``min(checkpoint_every, 500, steps // 4)`` steps, at the end, and, inside
:func:`setdiff_bench.runtime.interrupts.stop_at_safe_point` (the ``train`` verb), at the step where SIGINT or
SIGTERM arrived, before :class:`~setdiff_bench.runtime.interrupts.Interrupted` is raised.
Outputs in ``OUT``: ``checkpoints/step-<8-digit step>/`` (see :mod:`.checkpoint`), ``latest``,
``train_log.jsonl`` (losses every ``log_every`` steps), ``validation.jsonl`` (PSNR/SSIM[/LPIPS]
of the enhanced targets of the validation samples every ``validate_every`` steps) and ``samples.jsonl``
(per step, the ``[global position, packet id]`` of every sample drawn, all processes).  On resume, records
after the checkpoint's step (left by a killed run) are dropped before they are written again.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import random
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.metrics.ssim import ssim
from setdiff_bench.models.setdiff.checkpoint import (
    check_compatible,
    load_training_state,
    load_weights,
    mark_latest,
    read_config,
    resolve_checkpoint,
    save_checkpoint,
    step_folder,
)
from setdiff_bench.models.setdiff.config import Config, ModelConfig
from setdiff_bench.models.setdiff.files import LATEST_FILE, LOG_FILE, SAMPLES_FILE, VALIDATION_FILE
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.inputs import training_set
from setdiff_bench.models.setdiff.losses import ReconstructionLoss, latent_loss
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.runtime.interrupts import Interrupted, stop_requested
from setdiff_bench.types import TrainingSample


@dataclass
class TrainResult:
    """What :func:`train` did.

    Attributes:
        step: optimiser steps done in total (including those before a resume).
        checkpoint: the final checkpoint folder.
        losses: the last logged loss terms.
        validation: every validation record written during this call.
    """

    step: int
    checkpoint: Path
    losses: dict[str, float] = field(default_factory=dict)
    validation: list[dict[str, float]] = field(default_factory=list)


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
    ) -> None:
        if not 0 <= rank < world:
            raise ValueError(f"rank {rank} outside a world of {world}")
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
        """Dataset indices in the order the global sequence visits them during ``epoch``."""
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + epoch)
        return torch.randperm(len(self.dataset), generator=generator).tolist()  # type: ignore[arg-type]

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


def _identity(sample: Any) -> Any:
    return sample


def train(
    config: Config,
    dataset: Sequence[TrainingSample] | Iterable[TrainingSample],
    out_dir: str | Path,
    *,
    validation: Sequence[TrainingSample] = (),
    resume: bool = True,
    cpu: bool | None = None,
    progress: bool = True,
) -> TrainResult:
    """Train (or resume training) a model and write checkpoints to ``out_dir``.

    Args:
        config: model + training configuration.
        dataset: training samples (map-style datasets shuffle and resume exactly).
        out_dir: output folder (created); an existing run there is resumed when ``resume``.
        validation: samples scored every ``validate_every`` steps and at the end (main process).
        resume: continue from ``out_dir``'s latest checkpoint if there is one.
        cpu: force the CPU (default: CPU when CUDA is unavailable).
        progress: show a tqdm progress bar.

    Raises:
        CheckpointError: the checkpoint in ``out_dir`` belongs to another model configuration.
        WeightsError: LPIPS (loss weight > 0) or pretrained weights are missing.
    """
    from accelerate import Accelerator
    from accelerate.utils import DistributedDataParallelKwargs
    from tqdm.auto import tqdm

    tc = config.train
    cpu = (not torch.cuda.is_available()) if cpu is None else cpu
    precision = ("no" if cpu else "bf16") if tc.mixed_precision == "auto" else tc.mixed_precision
    ddp = DistributedDataParallelKwargs(find_unused_parameters=tc.reconstruction_weight == 0)
    accelerator = Accelerator(cpu=cpu, mixed_precision=precision, kwargs_handlers=[ddp])
    device = accelerator.device
    out = Path(out_dir)

    previous = None
    model_config = config.model
    if resume and ((out / LATEST_FILE).is_file()):
        previous = resolve_checkpoint(out)
        saved = read_config(previous)
        check_compatible(saved, config, previous)
        model_config = dataclasses.replace(
            model_config, learn_text_embedding=saved.model.learn_text_embedding
        )

    model = initial_model(model_config, tc.seed, load_pretrained=previous is None)
    config = dataclasses.replace(config, model=model.config)  # saved with the resolved text-embedding choice
    if previous is not None:
        load_weights(model, previous)
    if tc.gradient_checkpointing:
        model.unet.enable_gradient_checkpointing()
    model.to(device)
    model.train()
    optimizer = torch.optim.AdamW(
        model.trainable_parameters(),
        lr=tc.learning_rate,
        betas=tc.adam_betas,
        eps=tc.adam_eps,
        weight_decay=tc.weight_decay,
    )
    start = load_training_state(previous, optimizer) if previous is not None else 0
    reconstruction = (
        ReconstructionLoss(tc.l2_weight, tc.ssim_weight, tc.lpips_weight, tc.lpips_net, device=device)
        if tc.reconstruction_weight > 0
        else None
    )
    model, optimizer = accelerator.prepare(model, optimizer)
    core: SetDiffModel = accelerator.unwrap_model(model)
    rank, world = accelerator.process_index, accelerator.num_processes
    per_step = tc.gradient_accumulation * world  # samples per optimiser step, all processes together
    stream = SampleStream(
        dataset, seed=tc.seed, rank=rank, world=world, start=start * per_step, num_workers=tc.num_workers
    )
    main = accelerator.is_main_process
    if main and start > 0:  # records of steps after the checkpoint (a killed run) are redone now
        for name in (LOG_FILE, VALIDATION_FILE, SAMPLES_FILE):
            _truncate_jsonl(out / name, start)
    bar = tqdm(
        total=tc.steps,
        initial=start,
        disable=not (progress and main),
        desc=f"train {config.model.method}",
        dynamic_ncols=True,
    )
    result = TrainResult(step=start, checkpoint=previous or out)
    running: dict[str, float] = {}
    running_steps = 0
    began = time.perf_counter()

    for step in range(start, tc.steps):
        drawn: list[tuple[int, str]] = []
        for micro in range(tc.gradient_accumulation):
            # the sample's global position keys every random choice of its set: a run on N processes
            # draws exactly what one process with N-fold gradient accumulation draws
            position = (step * tc.gradient_accumulation + micro) * world + rank
            sample = next(stream)
            if stream.last is not None and stream.map_style and stream.last[0] != position:
                raise RuntimeError(f"sample stream at position {stream.last[0]}, expected {position}")
            drawn.append((position, sample.packet.packet_id))
            rng = random.Random(f"{tc.seed}/{position}")
            sync = micro == tc.gradient_accumulation - 1
            with contextlib.nullcontext() if sync else accelerator.no_sync(model):
                terms = _micro_step(model, core, sample, rng, config, reconstruction, accelerator)
            for key, value in terms.items():
                running[key] = running.get(key, 0.0) + value / tc.gradient_accumulation
        drawn = sorted(_gather_list(accelerator, drawn))
        if tc.grad_clip > 0:
            accelerator.clip_grad_norm_(model.parameters(), tc.grad_clip)
        optimizer.step()
        optimizer.zero_grad(set_to_none=True)
        running_steps += 1
        done = step + 1
        result.step = done
        if main:
            _append_jsonl(out / SAMPLES_FILE, {"step": done, "samples": [list(entry) for entry in drawn]})
        if done % tc.log_every == 0 or done == tc.steps:
            logged = {k: _gather_mean(accelerator, v / running_steps) for k, v in running.items()}
            running, running_steps = {}, 0
            result.losses = logged
            if main:
                bar.set_postfix({k: f"{v:.4f}" for k, v in logged.items()})
                _append_jsonl(
                    out / LOG_FILE, {"step": done, **logged, "seconds": round(time.perf_counter() - began, 3)}
                )
        bar.update(1)
        if validation and (done % tc.validate_every == 0 or done == tc.steps):
            # every process scores its share of the validation samples; the sums are reduced across them
            with accelerator.autocast():
                totals = validation_totals(
                    core, validation[: tc.validation_packets][rank::world], reconstruction
                )
            record = {"step": done, **_reduce_means(accelerator, totals)}
            result.validation.append(record)
            if main:
                _append_jsonl(out / VALIDATION_FILE, record)
                bar.write(
                    f"step {done}: " + ", ".join(f"{k} {v:.4f}" for k, v in record.items() if k != "step")
                )
        stopping = _any_process(accelerator, stop_requested())
        if done % checkpoint_interval(tc.checkpoint_every, tc.steps) == 0 or done == tc.steps or stopping:
            result.checkpoint = _save(accelerator, core, optimizer, config, out, done)
        if stopping:
            bar.close()
            raise Interrupted(
                f"stopped at step {done}/{tc.steps}; checkpoint {result.checkpoint}; "
                "rerun the same command to resume"
            )
    bar.close()
    if result.step == start and previous is None:
        result.checkpoint = _save(accelerator, core, optimizer, config, out, start)
    accelerator.wait_for_everyone()
    return result


def initial_model(model_config: ModelConfig, seed: int, *, load_pretrained: bool = True) -> SetDiffModel:
    """The model a training run with ``seed`` starts from: every random source is seeded
    (``accelerate.utils.set_seed``) right before the networks are built, so the same config and seed
    rebuild the same initial weights (e.g. to measure how far training moved them)."""
    from accelerate.utils import set_seed

    set_seed(seed)
    return SetDiffModel(model_config, load_pretrained=load_pretrained)


def _micro_step(
    model: Any,
    core: SetDiffModel,
    sample: TrainingSample,
    rng: random.Random,
    config: Config,
    reconstruction: ReconstructionLoss | None,
    accelerator: Any,
) -> dict[str, float]:
    """Forward + backward of one training set; returns the loss terms as floats."""
    tc, mc = config.train, config.model
    device = accelerator.device
    drawn = training_set(
        sample,
        rng,
        min_views=tc.min_views,
        max_views=tc.max_views,
        use_geometry=mc.use_geometry,
        cmap_clip=mc.cmap_clip,
        pairs=mc.method == "difix",
        geometry_inputs=mc.geometry_inputs,
        with_points=mc.attention_bias != "none",
        identity_probability=tc.identity_fraction,
        masked_copy_probability=tc.masked_copy_fraction,
    )
    batch = drawn.batch.to(device)
    keep = None
    if mc.use_geometry:
        keep = torch.tensor([0.0 if rng.random() < mc.geometry_dropout else 1.0], device=device)
    targets = batch.num_targets
    decode_index = None
    if reconstruction is not None:
        count = targets if tc.decode_targets <= 0 else min(tc.decode_targets, targets)
        decode_index = torch.tensor(sorted(rng.sample(range(targets), count)), device=device)
    gt = drawn.target_gt.to(device).flatten(0, 1)
    masks = drawn.target_masks.to(device).flatten(0, 1)
    prediction = model(batch, geometry_keep=keep, decode_index=decode_index)
    loss = torch.zeros((), device=device)
    terms: dict[str, float] = {}
    if tc.latent_weight > 0:
        with accelerator.autocast():
            gt_latents = core.encode(gt).latents
        latent = latent_loss(prediction.target_x0.flatten(0, 1), gt_latents, masks)
        loss = loss + tc.latent_weight * latent
        terms["latent"] = float(latent.detach())
    if reconstruction is not None and prediction.decoded is not None and decode_index is not None:
        recon = reconstruction(prediction.decoded.flatten(0, 1), gt[decode_index], masks[decode_index])
        loss = loss + recon["total"]
        terms.update({k: float(v.detach()) for k, v in recon.items() if k != "total"})
    terms["loss"] = float(loss.detach())
    accelerator.backward(loss / tc.gradient_accumulation)
    return terms


@torch.no_grad()
def validate(
    model: SetDiffModel, samples: Sequence[TrainingSample], reconstruction: ReconstructionLoss | None = None
) -> dict[str, float]:
    """Mean masked PSNR and SSIM (and LPIPS when the loss has it loaded) of enhanced vs ground-truth targets."""
    return _means(validation_totals(model, samples, reconstruction))


@torch.no_grad()
def validation_totals(
    model: SetDiffModel, samples: Sequence[TrainingSample], reconstruction: ReconstructionLoss | None = None
) -> dict[str, tuple[float, int]]:
    """Per metric, the sum over every target of ``samples`` and the number of targets (for reduction across
    processes): ``psnr`` and ``ssim`` (masked), ``lpips`` when the loss has LPIPS loaded."""
    was_training = model.training
    model.eval()
    scores: dict[str, list[float]] = {"psnr": [], "ssim": []}
    if reconstruction is not None and reconstruction.lpips is not None:
        scores["lpips"] = []
    try:
        for sample in samples:
            enhanced = enhance_packet(model, sample.packet)
            gt = sample.target_gt.float()
            masks = sample.target_masks.bool()
            scores["psnr"] += psnr(enhanced, gt, masks).tolist()
            scores["ssim"] += ssim(enhanced, gt, mask=masks).tolist()
            if "lpips" in scores:
                device = next(reconstruction.lpips.parameters()).device  # type: ignore[union-attr]
                composite = torch.where(masks, enhanced, gt).to(device)
                scores["lpips"] += reconstruction.lpips(composite, gt.to(device)).flatten().tolist()  # type: ignore[union-attr]
    finally:
        model.train(was_training)
    return {name: (float(sum(values)), len(values)) for name, values in scores.items()}


def _means(totals: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """``{metric: (sum, count)}`` → ``{metric: mean}``, leaving out metrics with no or non-finite values."""
    return {
        name: float(total / count)
        for name, (total, count) in totals.items()
        if count > 0 and math.isfinite(total)
    }


def _reduce_means(accelerator: Any, totals: dict[str, tuple[float, int]]) -> dict[str, float]:
    """Means over every process's targets from per-process ``(sum, count)`` pairs (same keys on all ranks)."""
    if accelerator.num_processes == 1:
        return _means(totals)
    names = sorted(totals)
    sums = torch.tensor([[totals[n][0], float(totals[n][1])] for n in names], dtype=torch.float64)
    sums = accelerator.reduce(sums.to(accelerator.device), reduction="sum").cpu()
    return _means({name: (total, count) for name, (total, count) in zip(names, sums.tolist(), strict=True)})


def _save(accelerator: Any, core: SetDiffModel, optimizer: Any, config: Config, out: Path, step: int) -> Path:
    folder = step_folder(out, step)
    accelerator.wait_for_everyone()
    if accelerator.is_main_process:
        save_checkpoint(folder, core, config, optimizer=optimizer, step=step)
        mark_latest(out, folder, config.train.keep_checkpoints)
    accelerator.wait_for_everyone()
    return folder


#: The longest interval between checkpoints, whatever the config says (steps).
MAX_CHECKPOINT_INTERVAL = 500


def checkpoint_interval(every: int, steps: int) -> int:
    """Steps between checkpoints: ``min(every, 500, steps // 4)`` (at least 1), so that a short run resumes too."""
    return max(1, min(every, MAX_CHECKPOINT_INTERVAL, steps // 4))


def _any_process(accelerator: Any, flag: bool) -> bool:
    """``flag`` or-ed over the processes, so that every rank stops (and saves) at the same step."""
    if accelerator.num_processes == 1:
        return flag
    return bool(
        accelerator.reduce(torch.tensor([float(flag)], device=accelerator.device), reduction="sum") > 0
    )


def _gather_list(accelerator: Any, items: list[Any]) -> list[Any]:
    """Every process's ``items``, concatenated (a collective: every rank must call it)."""
    if accelerator.num_processes == 1:
        return list(items)
    from accelerate.utils import gather_object

    return list(gather_object(items))


def last_validation(out: Path) -> dict[str, float] | None:
    """The newest record of ``out``'s ``validation.jsonl`` (``None`` when no validation ran).

    The manifest's ``"validation"`` comes from here when a session scored nothing itself (a no-op rerun of
    a finished run, an interruption between two validations), so it keeps the scores the file holds.
    """
    path = out / VALIDATION_FILE
    if not path.is_file():
        return None
    last = None
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line torn by a kill
        if isinstance(record, dict):
            last = record
    return last


def _truncate_jsonl(path: Path, last_step: int) -> None:
    """Keep the records of ``path`` up to ``last_step`` (and drop a line torn by a kill), atomically."""
    if not path.is_file():
        return
    kept = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(record, dict) and int(record.get("step", 0)) <= last_step:
            kept.append(line)
    write_text_atomic(path, "".join(line + "\n" for line in kept))


def _gather_mean(accelerator: Any, value: float) -> float:
    if accelerator.num_processes == 1:
        return float(value)
    tensor = torch.tensor([value], device=accelerator.device)
    return float(accelerator.gather(tensor).mean())


def _append_jsonl(path: Path, record: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", encoding="utf-8") as handle:
        handle.write(json.dumps(record, sort_keys=True) + "\n")
