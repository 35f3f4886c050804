"""``setdiff-bench run``: one enhancer over a packet store → enhanced PNGs, metrics.parquet, manifest.json.

See :mod:`setdiff_bench.evaluation.run` for the output layout, resume and shard semantics.

Examples::

    setdiff-bench run --method identity --packets runs/demo/work/packets --out runs/identity
    setdiff-bench run --method reproject --packets runs/demo/work/packets --out runs/reproject -o tolerance=0.05
    setdiff-bench run --method precomputed --from runs/identity/images --packets runs/demo/work/packets --out runs/mine
    setdiff-bench run --method precomputed --from my_outputs --name mymethod --packets runs/demo/work/packets \
        --out runs/demo/work/runs/mymethod
    setdiff-bench run --method setdiff --checkpoint tiny_setdiff --packets runs/demo/work/packets --out runs/sd --shard 0/2
    setdiff-bench run --method setdiff --checkpoint tiny_setdiff --packets runs/demo/work/packets --out runs/sd --shard 1/2
    setdiff-bench run --method setdiff --checkpoint tiny_setdiff --packets runs/demo/work/packets --out runs/sd --merge

``--inception FILE`` adds FID and KID of the enhanced targets against the recorded frames of the same
scenes (``<out>/distribution.parquet``; docs/any_capture.md), from a local Inception-v3 FID weights file.
Targets without ground truth (``prepare --trajectory``) are enhanced and written; the paired metrics they
cannot have (PSNR, SSIM, LPIPS) are named in one line (``skipped psnr, ssim, lpips for N target(s) without
ground truth ...``) and in the manifest, and their columns are null; warp error takes its flow from their
3DGS renders instead.

Shards (``--shard i/n``) may run at the same time on any machines into one folder on a shared
filesystem; no file lock is used.  The shard that finds every fragment present merges them; on a
network filesystem end with the same command plus ``--merge`` (it refuses while a fragment is missing).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from setdiff_bench.cli import (
    add_device_argument,
    add_option_argument,
    add_progress_argument,
    method_options,
    settings_from,
)
from setdiff_bench.cli.declared import declared_field_default, declared_literal
from setdiff_bench.models.setdiff.packaged import SPEEDS

#: Where the run's settings are declared (read from source: ``--help`` imports no torch).
RUN_SETTINGS_MODULE = "setdiff_bench.evaluation.run._settings"
RUN_SETTINGS = (RUN_SETTINGS_MODULE, "RunSettings")

VERB = "run"
HELP = "enhance every packet of a store with one method and score it (PSNR, SSIM, LPIPS; warp error)"
DESCRIPTION = __doc__


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", required=True, help="method name (`setdiff-bench list methods`)")
    parser.add_argument(
        "--packets", required=True, type=Path, help="packet store (`setdiff-bench prepare --out`)"
    )
    parser.add_argument(
        "--split", default="test", help="packets of this split: train, test or all (default test)"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="run folder (default results/runs/<store name>/<method>)"
    )
    parser.add_argument(
        "--shard", default="0/1", help="i/n: enhance packets i, i+n, ... (0 <= i < n); default 0/1"
    )
    add_device_argument(parser, "where the method and the metrics run")
    parser.add_argument(
        "--batch-size",
        type=int,
        default=declared_field_default(*RUN_SETTINGS, "batch_size"),
        help="images per metric call (memory bound)",
    )
    parser.add_argument(
        "--checkpoint", default=None, help="trained model for learned methods (setdiff, difix)"
    )
    parser.add_argument(
        "--from", dest="source", default=None, help="folder of images for --method precomputed"
    )
    parser.add_argument(
        "--name",
        default=None,
        help="the run's display name (default: the method's name): recorded in the manifest, shown by "
        "leaderboard, compare and report instead of the method, so that several precomputed methods share "
        "one table; letters, digits, _ . + -",
    )
    parser.add_argument(
        "--refit",
        default=None,
        metavar="DIR",
        help="the `setdiff-bench refit --out` folder whose refitted fits these packets were cut from (an X 3D "
        "run): each scene's refit manifest must be there; its time and memory join the run's manifest and "
        "leaderboard --cost",
    )
    parser.add_argument(
        "--speed",
        choices=SPEEDS,
        default=None,
        help="setdiff/difix speed preset: paper (the checkpoint as it is) or fast (a shipped SetDiff's "
        "one-pass student; quality cost in docs/performance.md); same as -o speed=NAME",
    )
    add_option_argument(parser, "method option, value parsed as JSON when valid (e.g. -o tolerance=0.05)")
    parser.add_argument(
        "--metrics",
        default="standard",
        help="metric preset (standard, gaussian_splatting, euvs_official) or comma list",
    )
    parser.add_argument(
        "--warp",
        choices=declared_literal(RUN_SETTINGS_MODULE, "WarpMode"),
        default=declared_field_default(*RUN_SETTINGS, "warp"),
        help="warp error per camera sequence (auto: on for nuScenes)",
    )
    parser.add_argument(
        "--flow",
        choices=declared_literal("setdiff_bench.metrics.optical_flow", "FlowMethod"),
        default=declared_field_default(*RUN_SETTINGS, "flow_method"),
        help="optical flow for warp error",
    )
    parser.add_argument(
        "--warp-cache",
        default="auto",
        metavar="DIR",
        help="cache of the optical flows warp error compares against (the ground truth's; the renders' for "
        "targets without), shared by methods (auto: the user cache; none: off)",
    )
    parser.add_argument(
        "--merge",
        action="store_true",
        help="enhance nothing: merge the fragments every shard wrote (refused while one is missing)",
    )
    parser.add_argument(
        "--no-verify",
        action="store_true",
        help="skip the up-front SHA-256 check of the packets' files (each file is still checked "
        "when it is read)",
    )
    parser.add_argument(
        "--inception",
        type=Path,
        default=None,
        metavar="FILE",
        help="FID Inception-v3 weights (pytorch-fid's pt_inception-2015-12-05-6726825d.pth or "
        "torch-fidelity's weights-inception-2015-12-05-6726825d.pth): also score FID / KID against the "
        "recorded frames; nothing is downloaded",
    )
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:

    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.evaluation.run import RunSettings, run_method
    from setdiff_bench.evaluation.scoring import resolve_metrics
    from setdiff_bench.io.run_layout import MANIFEST_FILE, METRICS_FILE
    from setdiff_bench.packets.shards import Shard
    from setdiff_bench.runtime.devices import resolve_device

    shard = Shard.parse(args.shard)
    device = resolve_device(args.device)
    options = method_options(args, "speed", path_flags=("checkpoint", "source"))
    metrics = tuple(spec.name for spec in resolve_metrics(args.metrics))
    settings = settings_from(
        RunSettings,
        args,
        options=options,
        split=None if args.split == "all" else args.split,
        metrics=metrics,
        flow_method=args.flow,
        device=device,
        warp_cache=None if args.warp_cache == "none" else args.warp_cache,
        refit=None if args.refit is None else str(Path(args.refit).expanduser().resolve()),
    )
    out = args.out or Path("results") / "runs" / Path(args.packets).resolve().name / settings.label
    inception = None
    if args.inception is not None:  # loaded first: a missing or wrong file stops the run before it writes
        from setdiff_bench.metrics.inception import load_inception

        inception = load_inception(args.inception, device)
    result = run_method(
        args.packets,
        out,
        settings,
        shard=shard,
        progress=False if args.no_progress else None,
        verify=not args.no_verify,
        merge_only=args.merge,
    )
    if not args.merge:
        print(
            f"{settings.label} [{shard}]: enhanced {result.enhanced} packets, {result.skipped} already done → {out}"
        )
    if result.skipped_metrics is not None:  # novel-trajectory targets: one line naming what was not scored
        print(result.skipped_metrics.line(distribution=inception is not None and result.merged))
    if result.merged:
        print(f"complete: {out / METRICS_FILE}, {out / MANIFEST_FILE}")
        if inception is not None:
            print_distribution(out, args.packets, inception, args.inception)
    else:
        print(
            f"{result.remaining} packets of the selection remain for other shards; "
            "the last shard to finish merges the results (or run the same command with --merge)",
            file=sys.stderr,
        )
    return 0


def print_distribution(run: Path, packets: Path, inception: object, weights: Path) -> None:
    """Score FID / KID of a finished run (:func:`setdiff_bench.evaluation.distribution_scoring.score_distribution`)
    and print one line per block and where the table is."""
    from setdiff_bench.evaluation.distribution_scoring import DISTRIBUTION_FILE, score_distribution
    from setdiff_bench.io.atomic import sha256_file

    score_distribution(  # type: ignore[arg-type]
        run,
        packets,
        inception,
        weights_sha256=sha256_file(weights),
        weights_file=weights.name,
        progress=print,
    )
    print(f"distribution: {run / DISTRIBUTION_FILE}")
