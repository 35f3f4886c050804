"""``setdiff-bench synth``: generate the synthetic street benchmark and fit each scene's 3DGS.

Scenes are written in the EUVS layout (docs/synthetic_format.md) as ``<out>/scene_<seed>_<index>/``;
unless ``--no-fit``, the 3DGS fitted on each scene's ``train_set.txt`` frames (the ``lane0`` front
camera minus the held-out interpolation frames) is written to ``<scene>/fits/lane0.ply``.  Finished
scenes and fits are kept on a rerun (``--overwrite`` redoes them); an interrupted fit resumes from
its checkpoint in ``<scene>/fits/lane0.checkpoint/``, which is removed once the PLY is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path

VERB = "synth"
HELP = "generate synthetic multi-lane street scenes (EUVS layout) and fit their 3DGS"
FIT_NAME = "lane0"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, type=Path, help="output folder (one sub-folder per scene)")
    parser.add_argument("--preset", default="default", choices=("tiny", "default", "large"),
                        help="tiny: seconds, for tests; default: ~10 min on 2 CPU cores; large: for a GPU")
    parser.add_argument("--seed", type=int, default=0, help="base seed; scene i uses (seed, i)")
    parser.add_argument("--scenes", type=int, default=None, help="number of scenes (default: the preset's)")
    parser.add_argument("--no-fit", action="store_true", help="only generate the scenes")
    parser.add_argument("--device", default=None,
                        help="cpu or cuda for rendering and fitting (default: cuda if available)")
    parser.add_argument("--overwrite", action="store_true", help="regenerate and refit existing scenes")
    parser.add_argument("--jobs", type=int, default=0,
                        help="scenes processed in parallel, one torch thread each (default: one per CPU core, "
                             "1 on CUDA); the CPU rasteriser's many small ops scale better across processes")
    parser.add_argument("--no-progress", action="store_true", help="hide progress bars")


def fit_path(scene_dir: Path) -> Path:
    """Where ``synth`` writes a scene's fit: ``<scene>/fits/lane0.ply``."""
    return scene_dir / "fits" / f"{FIT_NAME}.ply"


def make_scene(out: Path, preset_name: str, seed: int, index: int, count: int, *, fit: bool, device: str,
               overwrite: bool, progress: bool, threads: int | None = None) -> str:
    """Generate (and fit) scene ``index``; returns a one-line summary.  Runs in a worker process with ``--jobs``."""
    import shutil
    import time

    import torch
    from tqdm.auto import tqdm

    from setdiff_bench.gaussians.fit import fit_scene
    from setdiff_bench.synthetic.generate import generate_scene
    from setdiff_bench.synthetic.presets import get_preset

    if threads is not None:
        torch.set_num_threads(threads)
    preset = get_preset(preset_name)
    t0 = time.perf_counter()
    bar = tqdm(total=None, desc=f"scene {index + 1}/{count} render", unit="frame", disable=not progress, leave=False)

    def report(done: int, total: int) -> None:
        bar.total = total
        bar.update(done - bar.n)

    scene_dir = generate_scene(out, preset, seed, index, overwrite=overwrite, progress=report, device=device)
    bar.close()
    t1 = time.perf_counter()
    message = f"{scene_dir.name}: generated in {t1 - t0:.1f} s"
    if fit:
        ply = fit_path(scene_dir)
        if overwrite or not ply.is_file():
            checkpoint = ply.with_suffix(".checkpoint")
            if overwrite:
                shutil.rmtree(checkpoint, ignore_errors=True)
            result = fit_scene(scene_dir, ply, preset.fit, device=device, checkpoint_dir=checkpoint,
                               checkpoint_every=max(1, preset.fit.iterations // 5), progress=progress)
            shutil.rmtree(checkpoint, ignore_errors=True)
            message += f", fitted {len(result.model)} Gaussians in {time.perf_counter() - t1:.1f} s"
        else:
            message += ", fit already present"
    return message


def run(args: argparse.Namespace) -> int:
    import multiprocessing
    import time
    from concurrent.futures import ProcessPoolExecutor

    import torch

    from setdiff_bench.errors import UsageError
    from setdiff_bench.synthetic.presets import get_preset
    from setdiff_bench.threads import compute_threads

    preset = get_preset(args.preset)
    count = preset.num_scenes if args.scenes is None else args.scenes
    if count < 1:
        raise UsageError(f"--scenes must be ≥ 1, got {count}", "--scenes")
    if args.seed < 0:
        raise UsageError(f"--seed must be ≥ 0, got {args.seed}", "--seed")
    device = args.device or ("cuda" if torch.cuda.is_available() else "cpu")
    cores = compute_threads()  # the machine's CPU count unless SETDIFF_THREADS says otherwise
    jobs = args.jobs or (1 if device.startswith("cuda") else min(count, cores))
    if jobs < 1:
        raise UsageError(f"--jobs must be ≥ 1, got {jobs}", "--jobs")
    start = time.perf_counter()
    options = {"fit": not args.no_fit, "device": device, "overwrite": args.overwrite}
    if jobs == 1:
        for index in range(count):
            print(make_scene(args.out, preset.name, args.seed, index, count, progress=not args.no_progress,
                             **options), flush=True)
    else:
        threads = max(1, cores // jobs)
        with ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn")) as pool:
            futures = [pool.submit(make_scene, args.out, preset.name, args.seed, index, count, progress=False,
                                   threads=threads, **options) for index in range(count)]
            for future in futures:
                print(future.result(), flush=True)
    print(f"{count} scene(s) in {args.out} ({time.perf_counter() - start:.1f} s, {jobs} job(s))")
    return 0
