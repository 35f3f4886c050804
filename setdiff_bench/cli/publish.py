"""``setdiff-bench publish --run runs/demo --to results/synthetic``: replace published results on purpose.

Examples::

    setdiff-bench demo --train --setdiff-steps 1000 --difix-steps 1000
    setdiff-bench publish --run runs/demo --to results/synthetic

The destination is replaced whole by the run's files (not its ``work/`` folder) plus
``provenance.json``: the git revision, the demo command, seed, torch thread count, versions, and each
file's SHA-256.  Refused when the run is unfinished, an output changed after the demo, or the code had
uncommitted changes (``--allow-dirty`` publishes anyway and records it).
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

VERB = "publish"
HELP = "replace a published results folder by a finished demo run, whole and with provenance"
DESCRIPTION = __doc__


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--run", required=True, type=Path, help="the demo's --out folder (a finished run)")
    parser.add_argument(
        "--to",
        required=True,
        type=Path,
        dest="destination",
        help="published folder to replace, e.g. results/synthetic",
    )
    parser.add_argument(
        "--allow-dirty",
        action="store_true",
        help="publish a run made with uncommitted code changes (recorded as dirty)",
    )


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.pipeline.publish import PROVENANCE_FILE, publish

    command = "setdiff-bench " + shlex.join(
        ["publish", "--run", str(args.run), "--to", str(args.destination)]
        + (["--allow-dirty"] if args.allow_dirty else [])
    )
    manifest = publish(args.run, args.destination, command=command, allow_dirty=args.allow_dirty)
    print(
        f"published {len(manifest['files'])} files from {args.run} to {args.destination} "
        f"(revision {manifest['git']['revision'][:12]}; {args.destination / PROVENANCE_FILE})"
    )
    return 0
