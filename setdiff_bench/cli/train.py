"""``setdiff-bench train --config FILE --packets DIR --out CKPT_DIR``: train SetDiff or DiFix.

The config (a TOML file, or a packaged one by name: ``tiny_setdiff``, ``tiny_difix``,
``sd_turbo_setdiff``, ``sd_turbo_difix``) says which method and architecture; training samples come
from the packet store's ``train`` split, validation packets from its ``test`` split.  Re-running the
same command resumes from ``CKPT_DIR/latest``; a checkpoint of another configuration is refused.
Checkpoints are saved every min(checkpoint_every, 500, steps/4) steps, and on Ctrl-C or SIGTERM at
the step in progress (exit code 130; a second Ctrl-C stops at once).
Several GPUs: ``accelerate launch -m setdiff_bench.cli.main train ...`` (DDP, one process per GPU).

``setdiff-bench train autoencoder --packets DIR --out AE_DIR`` trains the tiny autoencoder that the
tiny configs freeze as their VAE (see :mod:`setdiff_bench.models.setdiff.autoencoder`) on the
ground-truth frames of the store's ``train`` split; re-running it resumes.

The examples use the packets of ``setdiff-bench demo --train``, which have a ``train`` split.  Examples::

    setdiff-bench train --config tiny_setdiff --packets runs/demo/work/packets --out runs/ckpt/setdiff --steps 200
    setdiff-bench train autoencoder --packets runs/demo/work/packets --out runs/ae --steps 1200 --crop 48 \\
        --batch-size 8 --latent-channels 8
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_progress_argument

VERB = "train"
HELP = "train a SetDiff or DiFix enhancer on a packet store"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "model",
        nargs="?",
        default="enhancer",
        choices=("enhancer", "autoencoder"),
        help="what to train: an enhancer (default; needs --config) or the tiny autoencoder",
    )
    parser.add_argument(
        "--config",
        metavar="FILE",
        help="TOML config, or a packaged name: tiny_setdiff, tiny_difix, sd_turbo_setdiff, sd_turbo_difix",
    )
    parser.add_argument(
        "--packets", required=True, metavar="DIR", type=Path, help="packet store (setdiff-bench prepare)"
    )
    parser.add_argument(
        "--out", required=True, metavar="CKPT_DIR", type=Path, help="output folder for checkpoints"
    )
    parser.add_argument("--steps", type=int, help="override [train] steps")
    parser.add_argument("--seed", type=int, help="override [train] seed")
    parser.add_argument(
        "--pretrained", metavar="DIR", help="local diffusers SD-Turbo folder (overrides [model])"
    )
    parser.add_argument("--validation-split", default="test", help="packet split scored during training")
    parser.add_argument(
        "--no-resume", action="store_true", help="refuse to continue an existing run in CKPT_DIR"
    )
    add_device_argument(
        parser,
        "where the enhancer or autoencoder trains (several GPUs: accelerate launch, enhancers only)",
        "auto (cuda when available, else cpu), cpu or cuda",
    )
    parser.add_argument(
        "--cpu", dest="device", action="store_const", const="cpu", help=argparse.SUPPRESS
    )  # the older spelling of --device cpu, kept for one release
    add_progress_argument(parser)
    autoencoder = parser.add_argument_group("autoencoder options")
    defaults = _autoencoder_defaults()
    for name, value in defaults.items():
        if name not in ("seed", "steps"):
            autoencoder.add_argument(
                "--" + name.replace("_", "-"),
                type=type(value),
                default=value,
                help=f"autoencoder {name.replace('_', ' ')} (default {value})",
            )


def _autoencoder_defaults() -> dict[str, int | float]:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from dataclasses import asdict

    from setdiff_bench.models.setdiff.autoencoder_settings import AutoencoderTraining

    return asdict(AutoencoderTraining())


def run_autoencoder(args: argparse.Namespace) -> int:
    from setdiff_bench.models.setdiff.autoencoder_settings import AutoencoderTraining
    from setdiff_bench.models.setdiff.autoencoder_train import check_settings, train_autoencoder
    from setdiff_bench.packets.store import PacketStore
    from setdiff_bench.runtime.devices import resolve_device

    values = {name: getattr(args, name) for name in _autoencoder_defaults() if name not in ("seed", "steps")}
    defaults = AutoencoderTraining()
    settings = AutoencoderTraining(
        **values, steps=args.steps or defaults.steps, seed=defaults.seed if args.seed is None else args.seed
    )
    check_settings(settings)  # every refusal before the note below
    store = PacketStore(args.packets)
    _check_split(store, "train", args.packets)
    rows = store.index[store.index["split"] == "train"]
    height, width = int(rows["height"].min()), int(rows["width"].min())
    if args.crop > min(height, width):  # said, not silent: random_crops clips the crop to the frame
        clipped = f"{min(args.crop, height) // 8 * 8}x{min(args.crop, width) // 8 * 8}"
        print(
            f"note: --crop {args.crop} is larger than the {height}x{width} training frames; the crops are "
            f"{clipped} (height x width, clipped to the frame)",
            file=sys.stderr,
        )
    manifest = train_autoencoder(
        args.packets, args.out, settings, device=resolve_device(args.device), progress=not args.no_progress
    )
    test = manifest["reconstruction_test"] or {}
    print(
        f"trained autoencoder ({manifest['train_frames']} frames, {settings.steps} steps, "
        f"{manifest['wall_seconds']:.0f} s): {args.out}; reconstruction PSNR train "
        f"{manifest['reconstruction_train']['psnr']:.2f} dB"
        + (f", test {test['psnr']:.2f} dB" if test else "")
    )
    return 0


def run(args: argparse.Namespace) -> int:
    from setdiff_bench.errors import UsageError
    from setdiff_bench.models.setdiff.config import with_overrides
    from setdiff_bench.models.setdiff.config_io import load_config
    from setdiff_bench.models.setdiff.files import LATEST_FILE
    from setdiff_bench.models.setdiff.train import train, training_device
    from setdiff_bench.models.setdiff.train_log import last_validation
    from setdiff_bench.packets.index import NoGroundTruthError
    from setdiff_bench.packets.store import PacketStore
    from setdiff_bench.runtime.interrupts import Interrupted, stop_at_safe_point
    from setdiff_bench.types import TrainingSample

    if args.model == "autoencoder":
        return run_autoencoder(args)
    if not args.config:
        raise UsageError("training an enhancer needs --config (a TOML file or a packaged name)", "--config")
    config = with_overrides(load_config(args.config), steps=args.steps, seed=args.seed)
    if args.pretrained:
        config = dataclasses.replace(
            config, model=dataclasses.replace(config.model, pretrained=str(args.pretrained))
        )
    if args.no_resume and (args.out / LATEST_FILE).exists():
        raise UsageError(
            "output folder already holds a training run (drop --no-resume to continue it)", args.out
        )
    store = PacketStore(args.packets)
    _check_split(store, "train", args.packets)
    tc = config.train
    dataset = store.training_dataset(
        split="train", min_views=tc.min_views, max_views=tc.max_views, seed=tc.seed
    )
    validation = []
    if tc.validation_packets > 0:
        # the first packets whose targets all have ground truth: a novel-trajectory packet (no ground truth,
        # PacketStore.has_ground_truth) is skipped, not a reason to stop
        for packet_id in store.packet_ids(args.validation_split):
            if len(validation) == tc.validation_packets:
                break
            try:
                gt, masks = store.load_ground_truth(packet_id)
            except NoGroundTruthError:
                continue
            validation.append(
                TrainingSample(packet=store.load_packet(packet_id), target_gt=gt, target_masks=masks)
            )
    began, start_step = time.perf_counter(), _latest_step(args.out)
    try:
        with stop_at_safe_point():  # Ctrl-C / SIGTERM: checkpoint at the current step, then exit 130
            result = train(
                config,
                dataset,
                args.out,
                validation=validation,
                resume=not args.no_resume,
                device=training_device(args.device),
                progress=not args.no_progress,
            )
    except Interrupted:
        _record_session(
            args,
            config,
            store,
            start_step,
            _latest_step(args.out),
            time.perf_counter() - began,
            last_validation(args.out),
        )
        raise
    # a session that scored nothing (a no-op rerun of a finished run) keeps the newest recorded scores
    _record_session(
        args,
        config,
        store,
        start_step,
        result.step,
        time.perf_counter() - began,
        result.validation[-1] if result.validation else last_validation(args.out),
    )
    if int(os.environ.get("RANK", "0")) != 0:
        return 0  # several processes (accelerate launch): the main one prints the summary
    losses = ", ".join(f"{k} {v:.4f}" for k, v in result.losses.items())
    print(
        f"trained {config.model.method} to step {result.step}: {result.checkpoint}"
        + (f" ({losses})" if losses else "")
    )
    if result.validation:
        last = result.validation[-1]
        print("validation: " + ", ".join(f"{k} {v:.4f}" for k, v in last.items() if k != "step"))
    return 0


def _check_split(store: object, split: str, packets: Path) -> None:
    """Refuse a store without ``split`` packets, naming the splits it has (a test-only store, say).

    Raises:
        UsageError: no packet of ``split`` in ``store``.
    """
    from setdiff_bench.errors import UsageError

    if store.packet_ids(split):  # type: ignore[attr-defined]
        return
    index = getattr(store, "index", None)
    splits = sorted({str(s) for s in index["split"]}) if index is not None and len(index) else []
    raise UsageError(
        f"training reads the store's {split} split, and this store has no {split} packets "
        f"(its splits: {', '.join(splits) or 'none'}); prepare one with training scenes "
        "(setdiff-bench demo --train makes one)",
        packets,
    )


def _latest_step(out: Path) -> int:
    """The step of ``out``'s newest checkpoint (0 when there is none)."""
    from setdiff_bench.errors import CheckpointError
    from setdiff_bench.models.setdiff.checkpoint import resolve_checkpoint, saved_step

    try:
        return saved_step(resolve_checkpoint(out))
    except CheckpointError:
        return 0


def _record_session(
    args: argparse.Namespace,
    config: object,
    store: object,
    start_step: int,
    end_step: int,
    wall_seconds: float,
    validation: dict[str, float] | None,
) -> None:
    """Add this session to ``<out>/manifest.json`` (main process only; see :mod:`~setdiff_bench.models.setdiff.manifest`)."""
    from setdiff_bench.models.setdiff.manifest import record_training_session, training_data_record

    if int(os.environ.get("RANK", "0")) != 0:
        return
    record_training_session(
        args.out,
        command=args.command_line,
        method=config.model.method,
        config_name=str(args.config),
        seed=config.train.seed,
        steps=config.train.steps,
        start_step=start_step,
        end_step=end_step,
        wall_seconds=wall_seconds,
        data=training_data_record(store, "train"),
        validation=validation,
    )
