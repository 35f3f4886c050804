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
samples form one global sequence (see :class:`~setdiff_bench.models.setdiff.sample_stream.SampleStream`); sample ``g`` goes to process ``g % world``
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
import random
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.models.setdiff.checkpoint import (
    SET_ATTENTION_KEYS,
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
from setdiff_bench.models.setdiff.distill import check_student_config, distillation_targets, load_teacher
from setdiff_bench.models.setdiff.files import LATEST_FILE, LOG_FILE, SAMPLES_FILE, VALIDATION_FILE
from setdiff_bench.models.setdiff.inputs import training_set
from setdiff_bench.models.setdiff.losses import ReconstructionLoss, latent_loss
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.sample_stream import SampleStream, dataset_reference_counts
from setdiff_bench.models.setdiff.set_mixer import is_no_match_parameter
from setdiff_bench.models.setdiff.train_log import append_record, truncate_records
from setdiff_bench.models.setdiff.validation import reduce_means, validation_totals
from setdiff_bench.runtime.devices import resolve_device
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


def train(
    config: Config,
    dataset: Sequence[TrainingSample] | Iterable[TrainingSample],
    out_dir: str | Path,
    *,
    validation: Sequence[TrainingSample] = (),
    resume: bool = True,
    device: str | None = None,
    progress: bool = True,
) -> TrainResult:
    """Train (or resume training) a model and write checkpoints to ``out_dir``.

    Args:
        config: model + training configuration.
        dataset: training samples (map-style datasets shuffle and resume exactly).
        out_dir: output folder (created); an existing run there is resumed when ``resume``.
        validation: samples scored every ``validate_every`` steps and at the end (main process).
        resume: continue from ``out_dir``'s latest checkpoint if there is one.
        device: ``"cpu"``, ``"cuda"`` or ``"auto"``/``None`` (CUDA when available, else the CPU); accelerate
            places the processes on the GPUs itself, so a numbered GPU (``cuda:1``) is refused.
        progress: show a tqdm progress bar.

    Raises:
        CheckpointError: the checkpoint in ``out_dir`` belongs to another model configuration.
        WeightsError: LPIPS (loss weight > 0) or pretrained weights are missing.
        UsageError: ``device`` is not a torch device, names CUDA where none is available, or is a numbered GPU.
    """
    from tqdm.auto import tqdm

    out = Path(out_dir)
    run = _setup(config, dataset, out, resume=resume, cpu=training_device(device) == "cpu")
    tc, accelerator, start = run.config.train, run.accelerator, run.start
    bar = tqdm(
        total=tc.steps,
        initial=start,
        disable=not (progress and run.main),
        desc=f"train {run.config.model.method}",
        dynamic_ncols=True,
    )
    result = TrainResult(step=start, checkpoint=run.previous or out)
    running: dict[str, float] = {}
    running_steps = 0
    began = time.perf_counter()

    for step in range(start, tc.steps):
        drawn = _optimiser_step(run, step, running)
        running_steps += 1
        done = step + 1
        result.step = done
        if run.main:
            append_record(out / SAMPLES_FILE, {"step": done, "samples": [list(entry) for entry in drawn]})
        if done % tc.log_every == 0 or done == tc.steps:
            result.losses = _log_losses(run, done, running, running_steps, began, bar)
            running, running_steps = {}, 0
        bar.update(1)
        if validation and (done % tc.validate_every == 0 or done == tc.steps):
            result.validation.append(_validation_step(run, validation, done, bar))
        stopping = _any_process(accelerator, stop_requested())
        if done % checkpoint_interval(tc.checkpoint_every, tc.steps) == 0 or done == tc.steps or stopping:
            result.checkpoint = _save(accelerator, run.core, run.optimizer, run.config, out, done)
        if stopping:
            bar.close()
            raise Interrupted(
                f"stopped at step {done}/{tc.steps}; checkpoint {result.checkpoint}; "
                "rerun the same command to resume"
            )
    bar.close()
    if result.step == start and run.previous is None:
        result.checkpoint = _save(accelerator, run.core, run.optimizer, run.config, out, start)
    accelerator.wait_for_everyone()
    return result


def training_device(device: str | None = None) -> str:
    """``device`` resolved for training (:func:`~setdiff_bench.runtime.devices.resolve_device`): ``"cpu"`` or
    ``"cuda"``; accelerate places the processes on GPUs itself.

    Raises:
        UsageError: (naming ``--device``) not a torch device, CUDA where none is available, or a numbered GPU
            (``cuda:N``; choose GPUs with ``CUDA_VISIBLE_DEVICES`` or accelerate).
    """
    resolved = resolve_device(device)
    if resolved not in ("cpu", "cuda"):
        raise UsageError(
            f"train runs where accelerate puts it: pick GPUs with CUDA_VISIBLE_DEVICES or "
            f"`accelerate launch`, not --device {device}",
            "--device",
        )
    return resolved


@dataclass
class _Run:
    """One training run's state while it trains (:func:`_setup`)."""

    accelerator: Any
    model: Any  # as accelerate prepared it (DDP-wrapped on several processes)
    core: SetDiffModel  # the unwrapped model
    optimizer: Any
    reconstruction: ReconstructionLoss | None
    config: Config  # with the resolved text-embedding choice (what checkpoints save)
    out: Path
    start: int  # optimiser steps done before this call
    previous: Path | None  # the checkpoint resumed from
    stream: SampleStream
    teacher: SetDiffModel | None = None  # guidance distillation (:mod:`.distill`)
    teacher_scale: float = 1.0

    @property
    def main(self) -> bool:
        return bool(self.accelerator.is_main_process)


def _setup(
    config: Config,
    dataset: Sequence[TrainingSample] | Iterable[TrainingSample],
    out: Path,
    *,
    resume: bool,
    cpu: bool,
) -> _Run:
    """The accelerator, the model and optimiser (fresh, or restored from ``out``'s latest checkpoint), the
    reconstruction loss and the sample stream from the resumed step; records after that step are dropped."""
    from accelerate import Accelerator
    from accelerate.utils import DistributedDataParallelKwargs

    tc = config.train
    precision = ("no" if cpu else "bf16") if tc.mixed_precision == "auto" else tc.mixed_precision
    ddp = DistributedDataParallelKwargs(find_unused_parameters=tc.reconstruction_weight == 0)
    accelerator = Accelerator(cpu=cpu, mixed_precision=precision, kwargs_handlers=[ddp])
    device = accelerator.device

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
    teacher, teacher_scale = None, 1.0
    if tc.distill_from is not None:
        check_student_config(config)
        teacher, teacher_scale = load_teacher(config, device)
        if previous is None:  # the student starts as the teacher
            load_weights(model, resolve_checkpoint(tc.distill_from), optional=is_no_match_parameter)
    if tc.init_from is not None and previous is None:  # a fine-tune of a trained model
        source = resolve_checkpoint(tc.init_from)
        check_compatible(read_config(source), config, source, ignore=SET_ATTENTION_KEYS)
        load_weights(model, source, optional=is_no_match_parameter)
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
        dataset,
        seed=tc.seed,
        rank=rank,
        world=world,
        start=start * per_step,
        num_workers=tc.num_workers,
        sparsest_share=tc.sparsest_share,
        reference_counts=dataset_reference_counts(dataset) if tc.sparsest_share > 0 else None,
    )
    if accelerator.is_main_process and start > 0:  # records of steps after the checkpoint are redone now
        for name in (LOG_FILE, VALIDATION_FILE, SAMPLES_FILE):
            truncate_records(out / name, start)
    return _Run(
        accelerator,
        model,
        core,
        optimizer,
        reconstruction,
        config,
        out,
        start,
        previous,
        stream,
        teacher,
        teacher_scale,
    )


def _optimiser_step(run: _Run, step: int, running: dict[str, float]) -> list[tuple[int, str]]:
    """One optimiser step (``gradient_accumulation`` micro-batches); adds each loss term's share to
    ``running``; returns the ``(global position, packet id)`` of every sample drawn, all processes, sorted."""
    tc, accelerator = run.config.train, run.accelerator
    rank, world = accelerator.process_index, accelerator.num_processes
    drawn: list[tuple[int, str]] = []
    for micro in range(tc.gradient_accumulation):
        # the sample's global position keys every random choice of its set: a run on N processes
        # draws exactly what one process with N-fold gradient accumulation draws
        position = (step * tc.gradient_accumulation + micro) * world + rank
        sample = next(run.stream)
        if run.stream.last is not None and run.stream.map_style and run.stream.last[0] != position:
            raise RuntimeError(f"sample stream at position {run.stream.last[0]}, expected {position}")
        drawn.append((position, sample.packet.packet_id))
        rng = random.Random(f"{tc.seed}/{position}")
        sync = micro == tc.gradient_accumulation - 1
        with contextlib.nullcontext() if sync else accelerator.no_sync(run.model):
            terms = _micro_step(
                run.model,
                run.core,
                sample,
                rng,
                run.config,
                run.reconstruction,
                accelerator,
                teacher=None if run.teacher is None else (run.teacher, run.teacher_scale),
            )
        for key, value in terms.items():
            running[key] = running.get(key, 0.0) + value / tc.gradient_accumulation
    drawn = sorted(_gather_list(accelerator, drawn))
    if tc.grad_clip > 0:
        accelerator.clip_grad_norm_(run.model.parameters(), tc.grad_clip)
    run.optimizer.step()
    run.optimizer.zero_grad(set_to_none=True)
    return drawn


def _log_losses(
    run: _Run, done: int, running: Mapping[str, float], running_steps: int, began: float, bar: Any
) -> dict[str, float]:
    """The loss terms averaged over the steps since the last log (and the processes), shown on the bar and
    appended to the training log."""
    logged = {k: _gather_mean(run.accelerator, v / running_steps) for k, v in running.items()}
    if run.main:
        bar.set_postfix({k: f"{v:.4f}" for k, v in logged.items()})
        append_record(
            run.out / LOG_FILE, {"step": done, **logged, "seconds": round(time.perf_counter() - began, 3)}
        )
    return logged


def _validation_step(
    run: _Run, validation: Sequence[TrainingSample], done: int, bar: Any
) -> dict[str, float]:
    """Score the validation samples at step ``done``: every process scores its share, the sums are reduced
    across them; the record is appended to the validation log and shown."""
    tc, accelerator = run.config.train, run.accelerator
    rank, world = accelerator.process_index, accelerator.num_processes
    with accelerator.autocast():
        totals = validation_totals(
            run.core, validation[: tc.validation_packets][rank::world], run.reconstruction
        )
    record = {"step": done, **reduce_means(accelerator, totals)}
    if run.main:
        append_record(run.out / VALIDATION_FILE, record)
        bar.write(f"step {done}: " + ", ".join(f"{k} {v:.4f}" for k, v in record.items() if k != "step"))
    return record


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
    teacher: tuple[SetDiffModel, float] | None = None,
) -> dict[str, float]:
    """Forward + backward of one training set; returns the loss terms as floats.

    With ``teacher`` (model, CFG scale) the targets of every loss term are the teacher's guided outputs
    (:func:`.distill.distillation_targets`), not the ground truth."""
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
        with_points=mc.needs_points,
        snapped_points=mc.snapped_points,
        identity_probability=tc.identity_fraction,
        masked_copy_probability=tc.masked_copy_fraction,
        masked_copy_visible=tc.masked_copy_visible,
        set_shape=tc.set_shape,
        test_targets=tc.test_targets,
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
    guided = None
    if teacher is not None:
        with accelerator.autocast():
            guided = distillation_targets(teacher[0], batch, teacher[1], decode_index)
    loss = torch.zeros((), device=device)
    terms: dict[str, float] = {}
    if tc.latent_weight > 0:
        if guided is not None:
            target_latents = guided.target_x0.flatten(0, 1)
        else:
            with accelerator.autocast():
                target_latents = core.encode(gt).latents
        latent = latent_loss(prediction.target_x0.flatten(0, 1), target_latents, masks)
        loss = loss + tc.latent_weight * latent
        terms["latent"] = float(latent.detach())
    if reconstruction is not None and prediction.decoded is not None and decode_index is not None:
        wanted = (
            gt[decode_index] if guided is None or guided.decoded is None else guided.decoded.flatten(0, 1)
        )
        recon = reconstruction(prediction.decoded.flatten(0, 1), wanted, masks[decode_index])
        loss = loss + recon["total"]
        terms.update({k: float(v.detach()) for k, v in recon.items() if k != "total"})
    terms["loss"] = float(loss.detach())
    accelerator.backward(loss / tc.gradient_accumulation)
    return terms


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


def _gather_mean(accelerator: Any, value: float) -> float:
    if accelerator.num_processes == 1:
        return float(value)
    tensor = torch.tensor([value], device=accelerator.device)
    return float(accelerator.gather(tensor).mean())
