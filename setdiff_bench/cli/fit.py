"""``setdiff-bench fit``: fit a 3DGS model to a scene folder's training frames and write the standard PLY.

The scene is read through the dataset loaders (synthetic, EUVS, or any COLMAP scene); its sparse
points initialise the Gaussians.  With ``--dataset D --root R``, ``--scene`` names the scene under the root
and may be left out when the root holds exactly one.  ``--checkpoint DIR`` saves the full optimiser state
every ``--checkpoint-every`` iterations; rerunning the same command resumes from it.

Examples::

    setdiff-bench fit --scene runs/demo/work/scenes/scene_0000_02 --out runs/fit/lane0.ply --preset tiny
    setdiff-bench fit --scene runs/demo/work/scenes/scene_0000_02 --out runs/fit_long/lane0.ply \\
        --checkpoint runs/fit_long/state --iterations 2000
"""

from __future__ import annotations

import argparse
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_progress_argument
from setdiff_bench.cli.declared import declared_literal, registry_names
from setdiff_bench.cli.list import add_loader_option_argument, loader_options

VERB = "fit"
HELP = "fit 3D Gaussian Splatting to a scene's training frames and write the standard PLY"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from setdiff_bench.loaders import DATASETS

    parser.add_argument(
        "--scene",
        default=None,
        help="scene folder (synthetic, EUVS or COLMAP layout), or with --dataset the scene's name under "
        "--root (optional when the root holds one scene)",
    )
    parser.add_argument(
        "--dataset",
        default=None,
        choices=list(DATASETS),
        help="read the scene through this dataset's loader (with --root and -o options)",
    )
    parser.add_argument("--root", type=Path, default=None, help="dataset folder for --dataset")
    add_loader_option_argument(parser, "e.g. -o missing=skip, -o images_dir=images_4")
    parser.add_argument(
        "--init",
        default="auto",
        choices=declared_literal("setdiff_bench.gaussians.fit._triangulate", "InitMode"),
        help="initial Gaussians: auto = the scene's sparse points, else points triangulated from "
        "the known poses (pycolmap), else random points sized to the scene",
    )
    parser.add_argument(
        "--downscale",
        type=int,
        default=1,
        help="fit on images downscaled by this integer factor (intrinsics scaled to match)",
    )
    parser.add_argument("--out", required=True, type=Path, help="output PLY")
    parser.add_argument(
        "--frames",
        default=None,
        help="frames to fit: 'train' (default: the scene's training split), comma-separated "
        "names, or @FILE / FILE.txt with one name per line",
    )
    parser.add_argument(
        "--preset",
        default="default",
        choices=(*registry_names("setdiff_bench.synthetic.presets", "PRESETS"), "standard"),
        help="schedule: a synthetic preset's fit, or 'standard' (Inria 30k iterations)",
    )
    parser.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="override the number of iterations (the schedule is rescaled to it)",
    )
    add_device_argument(parser, "cpu fits with the torch rasteriser, cuda with gsplat")
    parser.add_argument("--seed", type=int, default=0, help="random seed (view order, splits)")
    parser.add_argument(
        "--checkpoint", type=Path, default=None, help="checkpoint folder (resumed if present)"
    )
    parser.add_argument("--checkpoint-every", type=int, default=100, help="iterations between checkpoints")
    add_progress_argument(parser)


def fit_config(preset: str, iterations: int | None, seed: int):  # -> FitConfig
    """The configuration for ``--preset``/``--iterations``/``--seed``."""
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    import dataclasses

    from setdiff_bench.errors import UsageError
    from setdiff_bench.gaussians.fit import FitConfig

    if iterations is not None and iterations < 1:
        raise UsageError(f"--iterations must be ≥ 1, got {iterations}", "--iterations")
    if preset == "standard":
        base = FitConfig()
    else:
        from setdiff_bench.synthetic.presets import get_preset

        base = get_preset(preset).fit
    if iterations is not None and iterations != base.iterations:
        base = base.rescaled(iterations)  # the schedule scales; every other setting stays the preset's
    return dataclasses.replace(base, seed=seed)


def chosen_scene(args: argparse.Namespace, options: dict[str, object]) -> str:
    """The scene to fit: ``--scene``, or with ``--dataset`` and no ``--scene`` the root's only scene.

    Raises:
        UsageError: (naming the flag to change) ``--root`` / ``-o`` without ``--dataset``, ``--dataset``
            without ``--root``, no ``--scene`` without ``--dataset``, or a root of several scenes.
        DatasetError: a root that holds no scene (from the dataset's lister).
    """
    from setdiff_bench.errors import DatasetError, UsageError

    if args.dataset is None and (args.root is not None or options):
        raise UsageError("--root and -o need --dataset", "--dataset")
    if args.dataset is not None and args.root is None:
        raise UsageError("--dataset needs --root (the dataset folder)", "--root")
    if args.scene is not None:
        return args.scene
    if args.dataset is None:
        raise UsageError(
            "needed: a scene folder, or --dataset D --root R (whose only scene is then fitted)", "--scene"
        )
    from setdiff_bench.loaders import list_scenes

    names = list_scenes(args.dataset, args.root, **options)
    if not names:
        raise DatasetError(f"no {args.dataset} scene under this root", args.root)
    if len(names) > 1:
        shown = ", ".join(names[:5]) + (", ..." if len(names) > 5 else "")
        raise UsageError(
            f"{args.root} holds {len(names)} {args.dataset} scenes ({shown}); pick one with --scene",
            "--scene",
        )
    return names[0]


def run(args: argparse.Namespace) -> int:
    import time

    from setdiff_bench.gaussians.fit import fit_scene
    from setdiff_bench.runtime.devices import resolve_device

    device = resolve_device(args.device)
    config = fit_config(args.preset, args.iterations, args.seed)
    frames = None
    if args.frames is not None:
        from setdiff_bench.gaussians.fit import parse_frame_list

        frames = parse_frame_list(args.frames)
    start = time.perf_counter()
    options = loader_options(args)
    scene = chosen_scene(args, options)
    source = Path(scene) if args.dataset is None else args.root
    result = fit_scene(
        source,
        args.out,
        config,
        frames=frames,
        device=device,
        checkpoint_dir=args.checkpoint,
        checkpoint_every=args.checkpoint_every if args.checkpoint else 0,
        progress=not args.no_progress,
        dataset=args.dataset,
        scene_name=scene if args.dataset else None,
        loader_options=options,
        downscale=args.downscale,
        init=args.init,
    )
    elapsed = time.perf_counter() - start
    final = sum(result.losses[-10:]) / max(1, len(result.losses[-10:])) if result.losses else float("nan")
    print(
        f"fitted {len(result.model)} Gaussians in {config.iterations} iterations ({elapsed:.1f} s, "
        f"final loss {final:.4f}) -> {args.out}"
    )
    return 0
