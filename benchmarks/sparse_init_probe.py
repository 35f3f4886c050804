"""Refit a sparse-view benchmark's walks the way a sparse-view 3DGS is made in practice, and cut their packets.

Today's ``sparse`` preset starts every n-view fit from the scene's ``points3D``: SfM-like points sampled on
surfaces seen in *all* 150 frames and coloured with their mean ground truth — geometry and colour the n
views never saw.  This script refits the test walks of a finished ``synth --preset sparse`` run from what
the n fit views alone provide, so that their headroom can be measured before any training
(``benchmarks/sparse_geometry_audit.py`` on the packets it writes):

* ``--init random``: random points (the fit's own random start, ``fit --init random``: uniform in the
  camera box grown by the scene radius, one per 4×4-pixel block), as 3DGS-Enhancer's dataset generator
  fits its low-quality n-view 3DGS (``train.py … --n_sparse n --train_lr --rand_init``, 30 000 iterations,
  xiliu8006/3dgs_dataset_generator ``dataset_generator/utils.py`` ``train_lr``);
* ``--init views``: SfM-like points of the n fit views only (:func:`~setdiff_bench.synthetic.sparse.
  fit_view_points`: seen in at least two of them, coloured by them) — what a perfect matcher would
  triangulate.  COLMAP on the views themselves (``fit --init triangulate``) finds 0 / 2 / 30 points at
  n = 3 / 6 / 9 on these 256×144 walks (50° apart at n = 3), below the fit's 100-point floor;
* ``--init video``: the scene's own ``points3D`` (today's preset), for a like-for-like schedule.

Each walk gets a folder ``<out>/scenes/<walk>/`` (its ``images_4`` and ``scene.json`` linked, its COLMAP
model rewritten with the chosen points), its fits ``<out>/scenes/<walk>/fits/n{k}.ply`` made by
``setdiff-bench fit`` with the sparse preset's schedule rescaled to ``--iterations``, and the test packets
of the chosen view counts ``<out>/packets`` by ``setdiff-bench prepare dl3dv --protocol
dl3dv_sparse_synthetic``.  Every step is kept on a rerun.

Usage::

    python benchmarks/sparse_init_probe.py --scenes runs/sparse/scenes --out runs/probe_random_1000 \\
        --init random --iterations 1000 --views 3
    python benchmarks/sparse_geometry_audit.py --packets runs/probe_random_1000/packets \\
        --scenes runs/probe_random_1000/scenes --group n3 --out benchmarks/results/sparse_preset_random_1000.json
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from setdiff_bench.loaders.colmap import read_colmap_model
from setdiff_bench.synthetic.sfm import SparsePoints
from setdiff_bench.synthetic.sparse import (
    IMAGES_DIR,
    build_sparse_scene,
    fit_view_points,
    fit_views,
    get_sparse_preset,
    write_sparse_model,
)

INITS = ("random", "views", "video")
PROTOCOL = "dl3dv_sparse_synthetic"


def toolkit(*arguments: str) -> None:
    """Run ``setdiff-bench <arguments>`` (this interpreter), failing loudly."""
    command = [sys.executable, "-m", "setdiff_bench", *arguments]
    print("+ setdiff-bench " + " ".join(arguments), flush=True)
    subprocess.run(command, check=True)


def walk_folder(source: Path, destination: Path, init: str, views: int) -> None:
    """``destination``: the walk's frames and description linked from ``source``, and its COLMAP model with
    the points ``init`` says for an ``views``-view fit (module docstring); kept when already written."""
    model = destination / "colmap" / "sparse" / "0"
    if (model / "points3D.bin").is_file():
        return
    destination.mkdir(parents=True, exist_ok=True)
    for name in (IMAGES_DIR, "scene.json"):
        link = destination / name
        if not link.exists():
            os.symlink((source / name).resolve(), link)
    description = json.loads((source / "scene.json").read_text(encoding="utf-8"))
    preset = get_sparse_preset(description["preset"])
    build = build_sparse_scene(preset, int(description["seed"]), int(description["index"]))
    if init == "views":
        indices = [int(name.split("_")[1].split(".")[0]) - 1 for name in fit_views(preset)[f"n{views}"]]
        points = fit_view_points(build, indices)
    elif init == "video":
        recorded = read_colmap_model(source / "colmap" / "sparse" / "0", distortion="ignore")
        points = SparsePoints(recorded.points3d, recorded.points_rgb)
    else:  # random: the model carries no points, the fit starts from its own random points
        points = SparsePoints(np.zeros((0, 3)), np.zeros((0, 3), np.uint8))
    write_sparse_model(build, points, destination)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", required=True, type=Path, help="a `synth --preset sparse` output folder")
    parser.add_argument("--out", required=True, type=Path, help="work folder (scenes/, packets/)")
    parser.add_argument("--init", required=True, choices=INITS, help="initial points (module docstring)")
    parser.add_argument("--iterations", type=int, required=True, help="fit iterations (schedule rescaled)")
    parser.add_argument("--views", type=int, default=3, help="the view count to fit (default 3)")
    parser.add_argument("--walk", action="append", help="walks to refit (default: every walk in --scenes)")
    args = parser.parse_args()
    walks = args.walk or sorted(p.parent.name for p in args.scenes.glob("*/scene.json"))
    if not walks:
        parser.error(f"--scenes {args.scenes}: no walk folders with a scene.json")
    scenes = args.out / "scenes"
    for walk in walks:
        description = json.loads((args.scenes / walk / "scene.json").read_text(encoding="utf-8"))
        preset = get_sparse_preset(description["preset"])
        folder = scenes / walk
        walk_folder(args.scenes / walk, folder, args.init, args.views)
        ply = folder / "fits" / f"n{args.views}.ply"
        if not ply.is_file():
            toolkit(
                "fit",
                "--dataset",
                "dl3dv",
                "--root",
                str(scenes),
                "--scene",
                walk,
                "-o",
                "distortion=ignore",
                "--init",
                "random" if args.init == "random" else "sparse",
                "--frames",
                ",".join(fit_views(preset)[f"n{args.views}"]),
                "--preset",
                "default",
                "--iterations",
                str(args.iterations),
                "--checkpoint",
                str(ply.with_suffix(".checkpoint")),
                "--checkpoint-every",
                str(max(1, args.iterations // 5)),
                "--out",
                str(ply),
                "--no-progress",
            )
            shutil.rmtree(ply.with_suffix(".checkpoint"), ignore_errors=True)
    toolkit(
        "prepare",
        "dl3dv",
        "--protocol",
        PROTOCOL,
        "--root",
        str(scenes),
        "--fits",
        str(scenes),
        "--out",
        str(args.out / "packets"),
        "--split",
        "test",
        "--group",
        f"n{args.views}",
        "--workers",
        "1",
        "--no-progress",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
