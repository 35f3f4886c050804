"""``setdiff-bench prepare <dataset>``: dataset + protocol + 3DGS fits → a packet store.

Examples::

    setdiff-bench prepare synthetic --root runs/demo/work/scenes --fits runs/demo/work/scenes --out runs/packets
    setdiff-bench prepare euvs --root /data/EUVS --fits fits/euvs --out packets/euvs --split test --workers 4
    setdiff-bench prepare dl3dv --root /data/DL3DV --fit --out packets/dl3dv --shard 0/8
    setdiff-bench prepare synthetic --root runs/demo/work/scenes --fits runs/demo/work/scenes --out runs/packets \\
        --trajectory shift:-3 --trajectory shift:-6

``--trajectory SPEC`` (repeatable) writes novel-trajectory packets instead of the protocol's groups: the
fit frames' cameras moved by ``shift:METRES`` (to the right; negative: left), ``yaw:DEGREES`` or a JSON
file of poses, rendered with C-maps and without ground truth; references are the recorded fit frames chosen
by Eq. 2; the group is the trajectory (``shift-3m``) and the split ``test``.  ``run`` scores them with FID /
KID (``--inception``) and names the paired metrics it skipped.  A camera leaving the scene is refused in
one line before anything is written.

``--pairs RECIPES`` writes training packets from the capture alone, instead of the protocol's groups:
``sparse:N`` (fit on every N-th recorded frame, targets the frames between), ``underfit:F`` (the fit stopped
at F = 0.25..0.75 of its iterations, targets the recorded frames), ``cross-camera[:CAMERA]`` (fit on one
camera, targets the others), ``cycle[:S]`` (a second fit on the scene fit's renders at the recorded cameras
shifted S = 1..6 m sideways, negative: left; targets the recorded frames).  Targets keep their ground truth;
references are recorded frames chosen by Eq. 2 (those the degraded fit saw; for ``underfit`` and ``cycle``
all but the packet's own targets); the group is the recipe (``sparse4``, ``cycle2m``).  With ``--fit`` the
degraded fits are made here (``<out>/fits/<scene>/<fit_key>@<recipe>.ply``).  Example::

    setdiff-bench prepare synthetic --root runs/demo/work/scenes --fit --fit-iterations 2000 --out runs/pairs \\
        --split train --pairs sparse:4,underfit:0.5

Fits are looked up as ``<fits>/<scene>/<fit_key>.ply`` (then ``<fits>/<scene>/fits/<fit_key>.ply``);
fit keys per protocol: see ``setdiff_bench.packets.prepare`` (EUVS ``level1..3``, Para-Lane ``clip_0``, nuScenes
``first_10s``, DL3DV ``n3/n6/n9``, synthetic ``lane0``).  A rerun skips complete packets.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_progress_argument, settings_from
from setdiff_bench.cli.declared import (
    dataset_names,
    declared_field_default,
    declared_literal,
    declared_value,
    registry_names,
)
from setdiff_bench.cli.list import add_loader_option_argument, loader_options

VERB = "prepare"
HELP = "turn a dataset and 3DGS fits into render/ground-truth packets for a protocol"
DESCRIPTION = __doc__
#: Where the 3DGS fit configuration is declared: ``--fit-iterations``' default is its ``iterations`` field.
FIT_CONFIG = ("setdiff_bench.gaussians.fit._config", "FitConfig")  # read from source: its defining module
PREPARE_SETTINGS = ("setdiff_bench.packets.prepare_settings", "PrepareSettings")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "dataset",
        choices=dataset_names(),
        metavar="DATASET",
        help="dataset key (`setdiff-bench list datasets`): %(choices)s",
    )
    parser.add_argument("--root", required=True, type=Path, help="dataset root")
    parser.add_argument("--protocol", help="packaged protocol name or a .toml path (default: the dataset's)")
    fits = parser.add_mutually_exclusive_group(required=True)
    fits.add_argument("--fits", type=Path, help="folder of 3DGS PLYs: <fits>/<scene>/<fit_key>.ply")
    fits.add_argument("--fit", action="store_true", help="fit each 3DGS here (written to <out>/fits/)")
    parser.add_argument("--out", required=True, type=Path, help="packet store folder")
    parser.add_argument(
        "--split",
        choices=declared_value(PREPARE_SETTINGS[0], "SPLIT_CHOICES"),
        default=declared_field_default(*PREPARE_SETTINGS, "split"),
        help="which scenes of the protocol's scene split (default: all)",
    )
    parser.add_argument(
        "--test-scene",
        action="append",
        dest="test_scenes",
        metavar="NAME",
        help="declare this scene a test scene (repeatable); every scene not named is then a "
        "train scene, in place of the protocol's scene split",
    )
    parser.add_argument(
        "--scene", action="append", dest="scenes", metavar="NAME", help="only this scene (repeatable)"
    )
    parser.add_argument(
        "--group",
        action="append",
        dest="groups",
        metavar="NAME",
        help="only this protocol group (repeatable), e.g. --group holdout8; default all",
    )
    parser.add_argument(
        "--trajectory",
        action="append",
        dest="trajectories",
        metavar="SPEC",
        help="novel trajectory (repeatable): shift:METRES (right; negative: left), yaw:DEGREES or a JSON "
        "file of poses; writes its packets (no ground truth, group e.g. shift+3m) instead of the "
        "protocol's groups",
    )
    parser.add_argument(
        "--pairs",
        action="append",
        metavar="RECIPES",
        help="training-pair recipes, comma-separated: sparse[:N] (fit on every N-th recorded frame, N >= 2, "
        "default 4), underfit[:F] (stop the fit at F = 0.25..0.75 of its iterations, default 0.5), "
        "cross-camera[:CAMERA] (fit on one camera), cycle[:S] (fit on the scene fit's renders at the "
        "cameras shifted S = 1..6 m sideways, negative: left, default 2); writes their packets (targets with "
        "ground truth, group e.g. sparse4) instead of the protocol's groups",
    )
    parser.add_argument("--workers", type=int, default=1, metavar="K", help="render processes (default 1)")
    parser.add_argument(
        "--shard", default="0/1", metavar="i/n", help="process work units i, i+n, ... (default 0/1)"
    )
    parser.add_argument("--threads", type=int, default=1, help="torch threads per render process (default 1)")
    parser.add_argument(
        "--backend",
        choices=("auto", *declared_literal("setdiff_bench.gaussians.render", "Backend")),
        default="auto",
        help="renderer (auto: gsplat on CUDA when installed, else torch)",
    )
    add_device_argument(parser, "the torch backend's device")
    add_loader_option_argument(parser, 'overrides the protocol\'s; e.g. -o level=1, -o version="v1.0-mini"')
    parser.add_argument(
        "--cmap-precision",
        choices=declared_literal(PREPARE_SETTINGS[0], "CmapPrecision"),
        default=declared_field_default(*PREPARE_SETTINGS, "cmap_precision"),
        help="C-map EXR precision (float32: exact geometry; half: ~3.5x smaller files)",
    )
    parser.add_argument(
        "--fit-iterations",
        type=int,
        default=None,
        help=f"3DGS iterations with --fit (default {declared_field_default(*FIT_CONFIG, 'iterations')}; "
        "with --fit-preset: the preset's schedule rescaled to them)",
    )
    parser.add_argument(
        "--fit-preset",
        choices=(*registry_names("setdiff_bench.synthetic.presets", "PRESETS"), "standard"),
        default=None,
        help="with --fit: the 3DGS configuration of a synthetic preset (as fit --preset), e.g. to make "
        "--pairs fits as the synthetic scenes' own fits were made",
    )
    add_progress_argument(parser, "--quiet")  # --quiet: the older name, hidden, kept for one release


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.packets.fits import DEFAULT_FIT_ITERATIONS
    from setdiff_bench.packets.prepare import prepare
    from setdiff_bench.packets.prepare_settings import PrepareSettings
    from setdiff_bench.packets.shards import Shard
    from setdiff_bench.runtime.devices import resolve_device

    options = loader_options(args)
    config = None
    if args.fit_preset is not None:
        from setdiff_bench.cli.fit import fit_config

        config = fit_config(args.fit_preset, args.fit_iterations, seed=0)
    settings = settings_from(
        PrepareSettings,
        args,
        shard=Shard.parse(args.shard),
        device=resolve_device(args.device),
        loader_options=options,
        fit_iterations=DEFAULT_FIT_ITERATIONS if args.fit_iterations is None else args.fit_iterations,
        fit_config=config,
        progress=not args.no_progress,
    )
    summary = prepare(args.dataset, args.root, args.out, settings)
    print(summary.line())
    return 0
