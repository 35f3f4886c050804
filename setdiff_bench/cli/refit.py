"""``setdiff-bench refit``: distil an enhancer's novel views back into a scene's 3DGS (the "X 3D" rows).

The scene is read as ``prepare`` reads it (dataset, --root, --scene, protocol); the novel poses are a protocol
group's targets (--group lane+2) or a trajectory (--trajectory shift:3), planned as ``prepare`` plans their
packets.  During the refit the enhancer is given packets of the current model's renders (RGB, C-maps) with the
real fit frames as references, exactly as ``run`` gives it stored packets; ground truth of the targets is never
read.  Output: OUT/<scene>/<fit_key>.ply and its manifest <fit_key>.refit.json beside it (several scenes may
share OUT); ``prepare --fits OUT`` then renders the refit scenes' packets, and ``run`` on them scores ``X 3D`` (--method identity) and ``X 3D+`` (--method X).
Interrupted, the same command resumes from OUT/<scene>/<fit_key>.refit-checkpoint/ and ends with the same bytes.  docs/refit.md.

Examples::

    setdiff-bench refit synthetic --root runs/demo/work/scenes --scene scene_0000_00 --fits runs/demo/work/scenes \
        --group lane+2 --method setdiff --checkpoint tiny_setdiff --steps 300 --out runs/refit/setdiff
    setdiff-bench refit synthetic --root runs/demo/work/scenes --scene scene_0000_00 --fits runs/demo/work/scenes \
        --trajectory shift:-3 --method difix --checkpoint tiny_difix --schedule one-shot --steps 300 \
        --out runs/refit/difix
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_option_argument, add_progress_argument, method_options
from setdiff_bench.refit.settings import SCHEDULE_PRESETS, RefitSettings

#: ``-o`` is the enhancer's option here (as in ``run``), so the loader's is spelt out in full.
REFIT_LOADER_OPTION_FLAGS = ("--loader-option",)

VERB = "refit"
HELP = "distil an enhancer's novel views back into a scene's 3DGS (X 3D); progressive or one-shot schedule"
DESCRIPTION = __doc__

#: One line per schedule setting (``--<name>``); defaults come from the chosen preset.
SETTING_HELP = {
    "steps": "optimiser steps of the refit, each on one real or pseudo-view",
    "update_every": "steps between pseudo-view updates (0: one update before the first step)",
    "pose_fraction": "how far each update moves the pseudo-views from the nearest training pose to the targets",
    "pseudo_weight": "loss weight w of a pseudo-view step (a real view's is 1)",
    "real_ratio": "share r of the steps that take a real training view",
    "seed": "seed of the real and pseudo-view orders",
    "checkpoint_every": "save a resumable checkpoint every this many steps",
    "snapshot_every": "also write the model every this many steps to OUT/snapshots/step-NNNNNN/ (0: never); "
    "each is the PLY of a refit with that many --steps",
    "min_fit_correlation": "refuse a fit whose renders' detail correlates less with the training views (another "
    "scene's fit)",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dataset", help="dataset loader key, as for prepare (`setdiff-bench list datasets`)")
    parser.add_argument("--root", required=True, type=Path, help="dataset root")
    parser.add_argument("--scene", required=True, help="the scene's name under the root")
    parser.add_argument("--protocol", default=None, help="packaged protocol or TOML (default: the dataset's)")
    add_option_argument(
        parser,
        "loader option, value parsed as JSON when valid, as prepare's -o (overrides the protocol's; e.g. "
        "--loader-option missing=skip); repeatable",
        REFIT_LOADER_OPTION_FLAGS,
    )
    parser.add_argument(
        "--test-scene",
        action="append",
        dest="test_scenes",
        metavar="NAME",
        help="declare this scene a test scene (repeatable; every scene not named is then a train scene), in "
        "place of the protocol's scene split, as for the prepare whose packets the refit is scored on",
    )
    parser.add_argument(
        "--group", default=None, help="protocol group whose targets are distilled (e.g. lane+2)"
    )
    parser.add_argument(
        "--trajectory",
        default=None,
        help="distil a novel trajectory instead: shift:METRES, yaw:DEGREES or poses .json",
    )
    parser.add_argument(
        "--fits", type=Path, default=None, help="fit PLYs as for prepare: DIR/<scene>/<fit_key>.ply"
    )
    parser.add_argument(
        "--fit-iterations",
        type=int,
        default=None,
        help="no --fits: fit the scene here first, this many iterations",
    )
    parser.add_argument(
        "--fit-checkpoint",
        type=Path,
        default=None,
        help="the fit's checkpoint folder (`fit --checkpoint`): Adam moments",
    )
    parser.add_argument("--method", required=True, help="enhancer (`setdiff-bench list methods`)")
    parser.add_argument(
        "--checkpoint", default=None, help="trained model for learned methods (setdiff, difix)"
    )
    parser.add_argument(
        "--from", dest="source", default=None, help="folder of images for --method precomputed"
    )
    add_option_argument(parser, "method option, value parsed as JSON when valid")
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument(
        "--schedule",
        default="progressive",
        choices=list(SCHEDULE_PRESETS),
        help="progressive (Difix3D+) or one-shot (3DGS-Enhancer); the options below override it",
    )
    for spec in dataclasses.fields(RefitSettings):
        if spec.name == "schedule":
            continue
        presets = {name: values.get(spec.name, spec.default) for name, values in SCHEDULE_PRESETS.items()}
        shown = (
            str(spec.default)
            if len(set(presets.values())) == 1
            else ", ".join(f"{name} {value}" for name, value in presets.items())
        )
        parser.add_argument(
            f"--{spec.name.replace('_', '-')}",
            type=type(spec.default),
            default=None,
            help=f"{SETTING_HELP[spec.name]} (default: {shown})",
        )
    add_device_argument(parser, "where the refit and the enhancer run")
    parser.add_argument("--backend", default="auto", help="renderer: auto, torch or gsplat (default auto)")
    add_progress_argument(parser)


def run(args: argparse.Namespace) -> int:
    from setdiff_bench.cli.list import loader_options
    from setdiff_bench.refit import RefitTask, refit_scene

    options = method_options(args, path_flags=("checkpoint", "source"))
    overrides = {
        f.name: getattr(args, f.name) for f in dataclasses.fields(RefitSettings) if f.name != "schedule"
    }
    settings = RefitSettings.preset(args.schedule, **overrides)
    task = RefitTask(
        dataset=args.dataset,
        root=args.root,
        scene=args.scene,
        out=args.out,
        method=args.method,
        method_options=options,
        group=args.group,
        trajectory=args.trajectory,
        protocol=args.protocol,
        loader_options=loader_options(args, REFIT_LOADER_OPTION_FLAGS),
        test_scenes=tuple(args.test_scenes) if args.test_scenes else None,
        fits=args.fits,
        fit_iterations=args.fit_iterations,
        fit_checkpoint=args.fit_checkpoint,
        device=args.device,
        backend=args.backend,
    )
    result = refit_scene(task, settings, progress=not args.no_progress)
    manifest = result.manifest
    if result.already_done:
        print(f"already refitted: {result.ply} ({result.manifest_path})")
        return 0
    timing = manifest["time"]
    resumed = f", resumed at step {result.resumed_at}" if result.resumed_at else ""
    print(
        f"refitted {manifest['scene']} ({manifest['group']}) with {args.method}, {settings.schedule}: "
        f"{settings.steps} steps, {manifest['updates']} updates of {manifest['pseudo_views']} pseudo-views, "
        f"{timing['s_per_step'] * 1000:.0f} ms/step + {timing['enhance_s']:.1f} s enhancing{resumed} -> {result.ply}"
    )
    return 0
