"""``setdiff-bench render``: render a 3DGS PLY at the cameras of a COLMAP model, or along a novel trajectory.

Writes, per view, ``<out>/<view>/rgb.png`` (8-bit), ``cmap.exr`` (float32 X, Y, Z: Eq. 1 world
coordinates), ``depth.exr`` (float32 accumulated z) and ``alpha.png`` (8-bit accumulated opacity).
Each file is written atomically; an interrupted run resumes by skipping complete views.
``<out>/render.json`` records what the views are made from (the PLY's and COLMAP files' SHA-256,
``--downscale``, ``--backend``, ``--cmap-bound``); a rerun into the same folder resumes only when they
match, and is refused in one line otherwise (render into another ``--out``, or delete the old one).

``--trajectory`` renders a novel trajectory instead of the COLMAP cameras themselves: ``shift:N`` (each
camera N scene units to its right; ``shift:-3`` is a 3 m lane shift to the left), ``yaw:D`` (each camera
turned D degrees to the right) or a JSON file of poses (``[{"name", "c2w", "K"?, "width"?, "height"?}]``;
:mod:`setdiff_bench.packets.trajectory`).  Views are named ``<view>@<trajectory>`` (``view_1@shift+3m``);
they have no ground truth.  A trajectory that leaves the scene (the fit's Gaussian centres, 1st–99th
percentile, joined with the recorded cameras, + 5 %), a non-rigid pose or a NaN is refused in one line before anything is written.

Examples::

    setdiff-bench render --ply runs/demo/work/scenes/scene_0000_02/fits/lane0.ply \\
        --colmap runs/demo/work/scenes/scene_0000_02/sparse/0 --out runs/renders
    setdiff-bench render --ply runs/demo/work/scenes/scene_0000_02/fits/lane0.ply \\
        --colmap runs/demo/work/scenes/scene_0000_02/sparse/0 --out runs/renders_half --downscale 2 \\
        --images lane1_front_000.png --device cpu
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from setdiff_bench.cli import add_device_argument, add_progress_argument
from setdiff_bench.cli.declared import declared_literal

VERB = "render"
HELP = "render a 3DGS PLY at COLMAP cameras: RGB, C-map, depth and alpha per view"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP
OUTPUT_FILES = ("rgb.png", "cmap.exr", "depth.exr", "alpha.png")
RECORD_FILE = "render.json"
RECORD_FORMAT = "setdiff-render/1"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--ply", required=True, type=Path, help="3DGS model (standard PLY)")
    parser.add_argument(
        "--colmap", required=True, type=Path, help="COLMAP sparse folder (cameras/images .bin or .txt)"
    )
    parser.add_argument("--out", required=True, type=Path, help="output folder")
    parser.add_argument(
        "--images", nargs="+", metavar="NAME", help="only these COLMAP image names (default: all)"
    )
    parser.add_argument(
        "--trajectory",
        default=None,
        metavar="SPEC",
        help="render a novel trajectory from the COLMAP cameras: shift:METRES (to the right), "
        "yaw:DEGREES (to the right) or a JSON file of poses; no ground truth exists for these views",
    )
    parser.add_argument(
        "--backend",
        choices=declared_literal("setdiff_bench.gaussians.render", "Backend"),
        default="torch",
        help="torch: the built-in rasterizer, any device (default); gsplat: the CUDA rasterizer of the "
        "gsplat package (needs a GPU and pip install setdiff-bench[gpu])",
    )
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
    import numpy as np
    import torch
    from tqdm import tqdm

    from setdiff_bench.errors import UsageError
    from setdiff_bench.gaussians.ply import read_ply
    from setdiff_bench.gaussians.render import render
    from setdiff_bench.io.atomic import write_text_atomic
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
    spec = None
    if args.trajectory is not None:
        from setdiff_bench.packets.trajectory import parse_trajectory

        spec = parse_trajectory(args.trajectory)
    record = render_record(args, model.images_file, spec)
    cameras = {}
    for name in names:
        camera = pinhole_camera(model.cameras[name])
        if args.downscale > 1:
            camera = camera.resized(
                max(1, round(camera.width / args.downscale)), max(1, round(camera.height / args.downscale))
            )
        cameras[name] = camera
    distorted = [n for n in names if is_distorted(model.cameras[n])]
    recorded_count = len(names)
    folders = {name: view_folder_name(name) for name in names}
    if spec is not None:
        from setdiff_bench.packets.trajectory import novel_cameras

        recorded_centres = np.stack([cameras[n].center for n in names])
        novel = novel_cameras(spec, [(view_folder_name(n), cameras[n]) for n in names])
        cameras = dict(novel)
        names = [name for name, _ in novel]
        folders = {name: name.replace("/", "__").replace("\\", "__") for name in names}
    done = [n for n in names if all((args.out / folders[n] / f).is_file() for f in OUTPUT_FILES)]
    check_resume(args.out, record, done)  # before anything is read further or written
    if distorted:  # said once, never silent: the renderer is pinhole
        print(
            f"note: {len(distorted)} of {recorded_count} camera(s) have lens distortion (first {distorted[0]!r}); "
            "rendered as the undistorted pinhole camera with the same K (fit and prepare undistort the "
            "captures to match)",
            file=sys.stderr,
        )
    gaussians = read_ply(args.ply).to(device)
    if spec is not None:  # every novel camera inside the scene, checked before anything is written
        from setdiff_bench.packets.trajectory import check_within_bounds, scene_bounds

        bounds = scene_bounds(gaussians.means.detach().cpu().numpy(), recorded_centres)
        check_within_bounds([(n, cameras[n]) for n in names], bounds, args.trajectory)
    args.out.mkdir(parents=True, exist_ok=True)
    if not (args.out / RECORD_FILE).is_file():
        write_text_atomic(args.out / RECORD_FILE, json.dumps(record, indent=1, sort_keys=True) + "\n")
    todo = [n for n in names if n not in done]
    for name in tqdm(todo, desc="render", unit="view", disable=True if args.no_progress else None):
        folder = args.out / folders[name]
        with torch.no_grad():
            out = render(gaussians, [cameras[name]], backend=args.backend, cmap_bound=args.cmap_bound)
        write_exr(folder / "cmap.exr", to_numpy_hwc(out.cmap[0]), ("X", "Y", "Z"))
        write_exr(folder / "depth.exr", to_numpy_hwc(out.depth[0]), ("Z",))
        write_png(folder / "alpha.png", to_numpy_hwc(out.alpha[0]))
        write_png(folder / "rgb.png", to_numpy_hwc(out.rgb[0]))  # last: its presence marks a complete view
    along = "" if spec is None else f" of trajectory {spec.label} (no ground truth)"
    print(f"rendered {len(todo)} view(s){along}, {len(names) - len(todo)} already complete, into {args.out}")
    return 0


def render_record(args: argparse.Namespace, images_file: Path, spec: Any = None) -> dict[str, Any]:
    """What a render folder's views are made from: the inputs' SHA-256 and the settings that change pixels.

    Args:
        args: the parsed ``render`` arguments (``ply``, ``downscale``, ``backend``, ``cmap_bound``).
        images_file: the COLMAP ``images.bin`` / ``images.txt`` read (its ``cameras`` file beside it counts too).
        spec: the parsed ``--trajectory`` (:class:`~setdiff_bench.packets.trajectory.TrajectorySpec`) or
            ``None``; recorded as its label, and a pose file's SHA-256.
    """
    from setdiff_bench.io.atomic import sha256_file

    cameras_file = images_file.with_name("cameras" + images_file.suffix)
    extra: dict[str, Any] = {}
    if spec is not None:  # only with a trajectory, so records of plain renders stay as they were
        extra["trajectory"] = spec.label
        if spec.path is not None:
            extra["trajectory_sha256"] = sha256_file(spec.path)
    return {
        **extra,
        "format": RECORD_FORMAT,
        "ply_sha256": sha256_file(args.ply),
        "colmap_sha256": {f.name: sha256_file(f) for f in (cameras_file, images_file)},
        "downscale": args.downscale,
        "backend": args.backend,
        "cmap_bound": args.cmap_bound,
    }


def check_resume(out: Path, record: dict[str, Any], done: list[str]) -> None:
    """Refuse to resume into ``out`` unless its ``render.json`` matches ``record``.

    A folder without ``render.json`` is accepted only while it holds none of the views asked for.

    Raises:
        UsageError: ``render.json`` names other inputs or settings, is unreadable, or is missing beside
            finished views.
    """
    from setdiff_bench.errors import UsageError

    path = out / RECORD_FILE
    advice = "render into another --out, or delete the old renders first"
    if not path.is_file():
        if done:
            raise UsageError(
                f"holds {len(done)} rendered view(s) but no {RECORD_FILE} saying what they were made from; "
                + advice,
                out,
            )
        return
    try:
        earlier = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise UsageError(f"unreadable render record ({error}); {advice}", path) from error
    if not isinstance(earlier, dict) or earlier.get("format") != RECORD_FORMAT:
        raise UsageError(f"not a {RECORD_FORMAT} record; {advice}", path)
    differences = []
    if earlier.get("ply_sha256") != record["ply_sha256"]:
        differences.append("another --ply (SHA-256 differs)")
    if earlier.get("colmap_sha256") != record["colmap_sha256"]:
        differences.append("another --colmap model (SHA-256 differs)")
    if (earlier.get("trajectory"), earlier.get("trajectory_sha256")) != (
        record.get("trajectory"),
        record.get("trajectory_sha256"),
    ):
        differences.append(f"--trajectory {earlier.get('trajectory') or 'not given'}")
    for setting in ("downscale", "backend", "cmap_bound"):
        if earlier.get(setting) != record[setting]:
            flag = "--" + setting.replace("_", "-")
            was, now = (
                "not given" if value is None else value for value in (earlier.get(setting), record[setting])
            )
            differences.append(f"{flag} {was} (now {now})")
    if differences:
        raise UsageError(f"these renders were made with {'; '.join(differences)}; {advice}", path)
