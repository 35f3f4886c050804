"""``setdiff-bench render``: render a 3DGS PLY at the cameras of a COLMAP model.

Writes, per view, ``<out>/<view>/rgb.png`` (8-bit), ``cmap.exr`` (float32 X, Y, Z: Eq. 1 world
coordinates), ``depth.exr`` (float32 accumulated z) and ``alpha.png`` (8-bit accumulated opacity).
Each file is written atomically; an interrupted run resumes by skipping complete views.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_progress_argument

VERB = "render"
HELP = "render a 3DGS PLY at COLMAP cameras: RGB, C-map, depth and alpha per view"
OUTPUT_FILES = ("rgb.png", "cmap.exr", "depth.exr", "alpha.png")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ply", required=True, type=Path, help="3DGS model (standard PLY)")
    parser.add_argument(
        "--colmap", required=True, type=Path, help="COLMAP sparse folder (cameras/images .bin or .txt)"
    )
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument(
        "--images", nargs="+", metavar="NAME", help="only these COLMAP image names (default: all)"
    )
    parser.add_argument("--backend", choices=("torch", "gsplat"), default="torch")
    add_device_argument(parser, "the torch backend's device (gsplat renders on cuda)")
    parser.add_argument(
        "--downscale",
        type=int,
        default=1,
        help="render at the image size divided by this integer (as fit --downscale)",
    )
    parser.add_argument(
        "--cmap-bound",
        type=float,
        default=None,
        help="clip Gaussian centres to ±BOUND around the origin in the C-map",
    )
    add_progress_argument(parser)


def view_folder_name(image_name: str) -> str:
    """A flat folder name for an image name that may contain '/' (e.g. Para-Lane timestamps)."""
    stem = image_name.rsplit(".", 1)[0] if "." in image_name.rsplit("/", 1)[-1] else image_name
    return stem.replace("/", "__").replace("\\", "__")


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    import torch
    from tqdm import tqdm

    from setdiff_bench.errors import UsageError
    from setdiff_bench.gaussians.ply import read_ply
    from setdiff_bench.gaussians.render import render
    from setdiff_bench.io.images import to_numpy_hwc, write_exr, write_png
    from setdiff_bench.loaders.colmap import read_colmap_model
    from setdiff_bench.runtime.devices import resolve_device
    from setdiff_bench.undistort import is_distorted, pinhole_camera

    device = resolve_device(args.device) if args.backend == "torch" else "cuda"
    model = read_colmap_model(args.colmap)
    names = list(model.cameras) if not args.images else list(args.images)
    missing = [n for n in names if n not in model.cameras]
    if missing:
        raise UsageError(f"images not in the COLMAP model: {', '.join(missing[:10])}", args.colmap)
    if args.downscale < 1:
        raise UsageError(f"--downscale must be ≥ 1, got {args.downscale}", "--downscale")
    cameras = {}
    for name in names:
        camera = pinhole_camera(model.cameras[name])
        if args.downscale > 1:
            camera = camera.resized(
                max(1, round(camera.width / args.downscale)), max(1, round(camera.height / args.downscale))
            )
        cameras[name] = camera
    distorted = [n for n in names if is_distorted(model.cameras[n])]
    if distorted:  # said once, never silent: the renderer is pinhole
        print(
            f"note: {len(distorted)} of {len(names)} camera(s) have lens distortion (first {distorted[0]!r}); "
            "rendered as the undistorted pinhole camera with the same K (fit and prepare undistort the "
            "captures to match)",
            file=sys.stderr,
        )
    gaussians = read_ply(args.ply).to(device)
    args.out.mkdir(parents=True, exist_ok=True)
    todo = [n for n in names if not all((args.out / view_folder_name(n) / f).is_file() for f in OUTPUT_FILES)]
    for name in tqdm(todo, desc="render", unit="view", disable=True if args.no_progress else None):
        folder = args.out / view_folder_name(name)
        with torch.no_grad():
            out = render(gaussians, [cameras[name]], backend=args.backend, cmap_bound=args.cmap_bound)
        write_exr(folder / "cmap.exr", to_numpy_hwc(out.cmap[0]), ("X", "Y", "Z"))
        write_exr(folder / "depth.exr", to_numpy_hwc(out.depth[0]), ("Z",))
        write_png(folder / "alpha.png", to_numpy_hwc(out.alpha[0]))
        write_png(folder / "rgb.png", to_numpy_hwc(out.rgb[0]))  # last: its presence marks a complete view
    print(f"rendered {len(todo)} view(s), {len(names) - len(todo)} already complete, into {args.out}")
    return 0
