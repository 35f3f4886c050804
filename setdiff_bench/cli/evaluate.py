"""``setdiff-bench evaluate``: score a finished run under an evaluation profile (paper, euvs_official, ...).

Examples::

    setdiff-bench evaluate runs/demo/work/runs/setdiff --profile paper --packets runs/demo/work/packets
    setdiff-bench evaluate results/runs/euvs-setdiff --profile euvs_official --packets packets/euvs \\
        --data /data/EUVS --dinov2 /weights/dinov2-base --euvs-compat-report
    setdiff-bench evaluate results/runs/dl3dv-setdiff --profile dl3dv_3dgs_enhancer --packets packets/dl3dv \\
        --data /data/DL3DV-10K/1K

Writes ``<run>/profiles/<profile>/{metrics,scenes,groups}.parquet`` and ``profile.json``; the leaderboard
tabulates them with ``--profile``.  Profiles and the official rules they follow: docs/evaluation_profiles.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_progress_argument

VERB = "evaluate"
HELP = "score a finished run under an evaluation profile (the official EUVS / 3DGS-Enhancer scoring)"
DESCRIPTION = (
    "Rescore a finished run's enhanced images under an evaluation profile: scoring size and filters, "
    "crop, metrics, per-scene or pooled averaging (profiles: paper, euvs_official, dl3dv_3dgs_enhancer).\n\n"
    + (__doc__.split("\n\n", 1)[1] if __doc__ else "")
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run", type=Path, help="a finished run folder (metrics.parquet, images/)")
    parser.add_argument("--profile", default="paper", help="evaluation profile (default: paper)")
    parser.add_argument("--packets", type=Path, required=True, help="the packet store the run was made on")
    parser.add_argument(
        "--data",
        type=Path,
        default=None,
        help="dataset root (official layout): original images and masks, for profiles that score "
        "at another size than the working one",
    )
    parser.add_argument(
        "--dinov2",
        type=Path,
        default=None,
        metavar="DIR",
        help="local DINOv2 transformers folder (config.json + model.safetensors) for the EUVS "
        "cosine and Final_Score; nothing is downloaded",
    )
    parser.add_argument(
        "--inception",
        type=Path,
        default=None,
        metavar="FILE",
        help="FID Inception-v3 weights file (pytorch-fid / torch-fidelity): also write FID and KID of the "
        "run's enhanced targets against the recorded frames (<run>/distribution.parquet); nothing is "
        "downloaded",
    )
    parser.add_argument(
        "--euvs-compat-report",
        action="store_true",
        help="print the frames where EUVS's positional mask pairing differs from ours",
    )
    add_device_argument(parser, "where metrics (and DINOv2) run")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.errors import SetDiffBenchError, UsageError
    from setdiff_bench.evaluation.profile_scoring import score_run
    from setdiff_bench.io.run_layout import EUVS_COMPAT_FILE
    from setdiff_bench.protocols.profiles import get_profile
    from setdiff_bench.runtime.devices import resolve_device

    device = resolve_device(args.device)
    profile = get_profile(args.profile)
    dinov2 = None
    if args.dinov2 is not None:
        if not profile.dinov2:
            raise UsageError(f"profile {profile.name} has no DINOv2 score", "--dinov2")
        from setdiff_bench.metrics.dinov2 import load_dinov2

        dinov2 = load_dinov2(args.dinov2, device)
    inception = None
    if args.inception is not None:  # loaded before anything is scored or written
        from setdiff_bench.metrics.inception import load_inception

        inception = load_inception(args.inception, device)
    if args.euvs_compat_report and not profile.name.startswith("euvs"):
        raise UsageError(
            "--euvs-compat-report applies to EUVS profiles (euvs_official)", "--euvs-compat-report"
        )
    if _without_ground_truth(args.run, args.packets):  # novel-trajectory targets: nothing paired to score
        if inception is None:
            raise UsageError(
                "every target of this run is a novel-trajectory view without ground truth: no profile "
                "metric applies; pass --inception FILE for FID / KID",
                args.run,
            )
        print(
            f"note: profile {profile.name} not scored: every target of this run is a novel-trajectory view "
            "without ground truth",
            file=sys.stderr,
        )
        from setdiff_bench.cli.run import print_distribution

        print_distribution(args.run, args.packets, inception, args.inception)
        return 0
    try:
        out = score_run(
            args.run,
            profile,
            packets=args.packets,
            data=args.data,
            dinov2=dinov2,
            device=device,
            progress=False if args.no_progress else None,
        )
    except SetDiffBenchError as error:
        other = _other_store(args.run, args.packets)
        if other is None:
            raise
        raise UsageError(other, "--packets") from error
    print(profile.caption(_scored_size(out, args.packets)))
    unlisted = _unlisted_by_protocol(out, profile.name)
    if unlisted:
        print(f"note: {unlisted}", file=sys.stderr)
    print(f"tables: {out}")
    if profile.dinov2 and dinov2 is None:
        print(
            "note: no --dinov2 weights given: Cos_Similarity and Final_Score are not computed",
            file=sys.stderr,
        )
    if args.euvs_compat_report:
        sys.stdout.write((out / EUVS_COMPAT_FILE).read_text())
    if inception is not None:
        from setdiff_bench.cli.run import print_distribution

        print_distribution(args.run, args.packets, inception, args.inception)
    return 0


def _without_ground_truth(run: Path, packets: Path) -> bool:
    """Whether every target ``run`` scored lacks ground truth (a run on ``prepare --trajectory`` packets
    only); ``False`` when the run or the store cannot be read (the profile scoring then says why)."""
    import pandas as pd

    from setdiff_bench.errors import SetDiffBenchError
    from setdiff_bench.io.run_layout import METRICS_FILE
    from setdiff_bench.packets.store import PacketStore, target_has_ground_truth

    try:
        scored = set(pd.read_parquet(run / METRICS_FILE, columns=["packet_id"])["packet_id"])
        index = PacketStore(packets).index
    except (OSError, ValueError, KeyError, SetDiffBenchError):
        return False
    rows = index[(index["role"] == "target") & index["packet_id"].isin(scored)]
    return bool(len(rows)) and not target_has_ground_truth(rows).any()


def _scored_size(tables: Path, packets: Path) -> tuple[int, int] | None:
    """``(height, width)`` of the targets a profile scored (from the store's index), or ``None`` when they
    differ or cannot be read, so that the caption states the real size (not the paper's 576x1024)."""
    import pandas as pd

    from setdiff_bench.errors import SetDiffBenchError
    from setdiff_bench.packets.store import PacketStore

    try:
        scored = set(pd.read_parquet(tables / "metrics.parquet", columns=["packet_id"])["packet_id"])
        index = PacketStore(packets).index
    except (OSError, ValueError, KeyError, SetDiffBenchError):
        return None
    rows = index[(index["role"] == "target") & index["packet_id"].isin(scored)]
    sizes = {(int(h), int(w)) for h, w in zip(rows["height"], rows["width"])}
    return sizes.pop() if len(sizes) == 1 else None


def _other_store(run: Path, packets: Path) -> str | None:
    """Why ``packets`` is not the store ``run`` was made from (its ``index.parquet`` differs from the one
    ``run.json`` records), or ``None`` when it is, or when either cannot be read."""
    import json

    from setdiff_bench.io.atomic import sha256_file
    from setdiff_bench.io.run_layout import RUN_FILE
    from setdiff_bench.packets.index import INDEX_FILE

    try:
        recorded = json.loads((run / RUN_FILE).read_text(encoding="utf-8"))["index_sha256"]
        actual = sha256_file(packets / INDEX_FILE)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if recorded == actual:
        return None
    return (
        f"{packets} is not the packet store {run} was made from (its {INDEX_FILE} differs from the one "
        f"{RUN_FILE} records); pass the run's own --packets"
    )


def _unlisted_by_protocol(tables: Path, profile: str) -> str | None:
    """Why ``profile`` is not one the run's protocol lists (its ``[evaluation] profiles``), or ``None`` when
    it is listed or the protocol cannot be read; said on stderr, since scoring any run under any profile is
    allowed (docs/evaluation_profiles.md compares profiles on one synthetic run)."""
    import pandas as pd

    from setdiff_bench.errors import SetDiffBenchError
    from setdiff_bench.protocols import load_protocol

    try:
        names = sorted(set(pd.read_parquet(tables / "metrics.parquet", columns=["protocol"])["protocol"]))
        listed = {name: tuple(load_protocol(name).evaluation) for name in names}
    except (OSError, ValueError, KeyError, SetDiffBenchError):
        return None
    outside = [name for name, profiles in listed.items() if profile not in profiles]
    if not outside:
        return None
    name = outside[0]
    return f"the {name} protocol lists the profiles {', '.join(listed[name])}, not {profile} (scored anyway)"
