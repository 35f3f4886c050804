"""``setdiff-bench synth``: generate the synthetic street benchmark and fit each scene's 3DGS.

Scenes are written in the EUVS layout (docs/synthetic_format.md) as ``<out>/scene_<seed>_<index>/``;
unless ``--no-fit``, the 3DGS fitted on each scene's ``train_set.txt`` frames (the ``lane0`` front
camera minus the held-out interpolation frames) is written to ``<scene>/fits/lane0.ply``.  Finished
scenes and fits are kept on a rerun (``--overwrite`` redoes them); an interrupted fit resumes from
its checkpoint in ``<scene>/fits/lane0.checkpoint/``, which is removed once the PLY is written.
Progress: one bar per scene at work on a terminal; in a log (stderr not a terminal) or with
``--no-progress``, a line when a scene starts rendering or fitting and at each quarter of its fit.

Examples::

    setdiff-bench synth --out runs/scenes --preset tiny --scenes 2
    setdiff-bench synth --out runs/scenes --indices 2 --no-fit
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from setdiff_bench.cli import add_device_argument, add_progress_argument
from setdiff_bench.cli.declared import registry_names
from setdiff_bench.synthetic.kinds import SCENE_KINDS, scene_kind_of

VERB = "synth"
HELP = "generate synthetic multi-lane street scenes (EUVS layout) and fit their 3DGS"
DESCRIPTION = __doc__.split("\n\n", 1)[1] if __doc__ else HELP


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", required=True, type=Path, help="output folder (one sub-folder per scene)")
    parser.add_argument(
        "--preset",
        default="default",
        # every scene kind's presets, read from the registries' sources: --help imports no torch
        choices=[name for kind in SCENE_KINDS.values() for name in registry_names(*kind.presets.split(":"))],
        help="tiny: seconds, for tests; default: ~10 min on 2 CPU cores; large: for a GPU; sparse*: "
        "handheld walks in DL3DV's layout with n3/n6/n9 fits (docs/synthetic_format.md)",
    )
    parser.add_argument("--seed", type=int, default=0, help="base seed; scene i uses (seed, i)")
    parser.add_argument("--scenes", type=int, default=None, help="number of scenes (default: the preset's)")
    parser.add_argument(
        "--indices",
        metavar="I,J,...",
        default=None,
        help="generate only these scene indices (0-based, comma-separated; scene i is the same "
        "whichever others are made), e.g. a preset's test scenes",
    )
    parser.add_argument("--no-fit", action="store_true", help="only generate the scenes")
    add_device_argument(parser, "rendering and fitting")
    parser.add_argument("--overwrite", action="store_true", help="regenerate and refit existing scenes")
    parser.add_argument(
        "--jobs",
        type=int,
        default=0,
        help="scenes processed in parallel, one torch thread each (default: one per CPU core, "
        "1 on CUDA); the CPU rasteriser's many small ops scale better across processes",
    )
    add_progress_argument(parser)


class ProgressEvents:
    """Where :func:`make_scene` reports progress: ``(kind, scene index, done, total)`` tuples put on a
    queue (a ``multiprocessing`` manager queue for worker processes) for :class:`SceneProgress`.

    ``kind`` is ``"render"`` (ground-truth frames) or ``"fit"`` (3DGS iterations, about every 1 %).
    """

    def __init__(self, queue: Any) -> None:
        self.queue = queue

    def __call__(self, kind: str, index: int, done: int, total: int) -> None:
        self.queue.put((kind, index, done, total))


class SceneProgress:
    """Per-scene progress in the main process: one tqdm bar per scene at work, or, without bars, a line
    when a scene starts rendering or fitting and at each quarter of its fit (so that a 10-minute
    ``synth`` never goes silent).

    Args:
        names: ``{scene index: scene name}`` of the scenes this run makes, in order; a scene is labelled
            by its position among them and its name (``scene 1/1 (scene_0000_02)`` for ``--indices 2``).
        bars: tqdm bars (a terminal) instead of lines (a log).
    """

    def __init__(self, names: dict[int, str], bars: bool) -> None:
        self.names, self.bars = names, bars
        self.position = {index: position for position, index in enumerate(names, start=1)}
        self.open: dict[int, Any] = {}
        self.phase: dict[int, str] = {}
        self.quarter: dict[int, int] = {}

    def update(self, kind: str, index: int, done: int, total: int) -> None:
        from tqdm.auto import tqdm

        position, name = self.position.get(index, index + 1), self.names.get(index)
        label = f"scene {position}/{len(self.names)} ({name}) {kind}"
        if self.phase.get(index) != kind:
            self.phase[index] = kind
            if index in self.open:
                self.open.pop(index).close()
            if self.bars:
                self.open[index] = tqdm(
                    total=total,
                    desc=label,
                    unit="frame" if kind == "render" else "it",
                    leave=False,
                    dynamic_ncols=True,
                )
            else:
                print(
                    f"{label}: started ({total} {'frames' if kind == 'render' else 'iterations'})", flush=True
                )
        if index in self.open:
            self.open[index].update(done - self.open[index].n)
        elif kind == "fit" and total and 4 * done // total > self.quarter.get(index, 0) and done < total:
            self.quarter[index] = 4 * done // total
            print(f"{label}: {done}/{total} iterations", flush=True)

    def finish(self, index: int) -> None:
        if index in self.open:
            self.open.pop(index).close()

    def close(self) -> None:
        for index in list(self.open):
            self.finish(index)


def make_scene(
    out: Path,
    preset_name: str,
    seed: int,
    index: int,
    count: int,
    *,
    fit: bool,
    device: str,
    overwrite: bool,
    report: Any = None,
    threads: int | None = None,
) -> str:
    """Generate (and fit) scene ``index``; returns a one-line summary.  Runs in a worker process with ``--jobs``.

    ``report(kind, index, done, total)`` receives render and fit progress (:class:`ProgressEvents`).
    """
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    import time

    from setdiff_bench.runtime.threads import set_process_threads

    if threads is not None:
        set_process_threads(threads)
    kind = scene_kind_of(preset_name)  # driving (EUVS layout, fits/lane0.ply) or sparse (DL3DV, n3/n6/n9)
    preset = kind.get_preset(preset_name)
    t0 = time.perf_counter()

    def rendered(done: int, total: int) -> None:
        if report is not None:
            report("render", index, done, total)

    scene_dir = kind.load_generator().make(
        out, preset, seed, index, overwrite=overwrite, progress=rendered, device=device
    )
    message = f"{scene_dir.name}: generated in {time.perf_counter() - t0:.1f} s"
    if not fit:
        return message
    fitter = kind.load_fitter()
    keys = fitter.keys(preset)

    def fitted(key: str, iteration: int, total: int) -> None:
        # the scene's fits one after the other on one bar
        if report is not None:
            report("fit", index, keys.index(key) * total + iteration, len(keys) * total)

    lines = fitter.fit(scene_dir, preset, device=device, overwrite=overwrite, report=fitted)
    return f"{message}, {', '.join(lines)}"


def parse_indices(text: str) -> list[int]:
    """``"2,4"`` → ``[2, 4]`` (sorted, distinct).

    Raises:
        UsageError: not a comma-separated list of integers ≥ 0.
    """
    from setdiff_bench.errors import UsageError

    try:
        indices = sorted({int(part) for part in text.split(",")})
    except ValueError:
        raise UsageError(f"--indices must be comma-separated integers, got {text!r}", "--indices") from None
    if indices[0] < 0:
        raise UsageError(f"--indices must be ≥ 0, got {text!r}", "--indices")
    return indices


def run(args: argparse.Namespace) -> int:
    import contextlib
    import multiprocessing
    import queue as queues
    import time
    from concurrent.futures import ProcessPoolExecutor

    from setdiff_bench.errors import UsageError
    from setdiff_bench.runtime.devices import resolve_device
    from setdiff_bench.runtime.threads import compute_threads

    kind = scene_kind_of(args.preset)
    preset = kind.get_preset(args.preset)
    count = preset.num_scenes if args.scenes is None else args.scenes
    if count < 1:
        raise UsageError(f"--scenes must be ≥ 1, got {count}", "--scenes")
    indices = list(range(count)) if args.indices is None else parse_indices(args.indices)
    if args.seed < 0:
        raise UsageError(f"--seed must be ≥ 0, got {args.seed}", "--seed")
    device = resolve_device(args.device)
    cores = compute_threads()  # the machine's CPU count unless SETDIFF_THREADS says otherwise
    jobs = args.jobs or (1 if device.startswith("cuda") else min(len(indices), cores))
    if jobs < 1:
        raise UsageError(f"--jobs must be ≥ 1, got {jobs}", "--jobs")
    start = time.perf_counter()
    options = {"fit": not args.no_fit, "device": device, "overwrite": args.overwrite}
    names = {index: kind.scene_name(args.seed, index) for index in indices}  # as the generator names them
    bars = not args.no_progress and sys.stderr.isatty()  # no bars in a log: lines instead
    progress = SceneProgress(names, bars=bars)
    try:
        if jobs == 1:
            for index in indices:
                message = make_scene(
                    args.out, preset.name, args.seed, index, count, report=progress.update, **options
                )
                progress.finish(index)
                print(message, flush=True)
        else:
            threads = max(1, cores // jobs)
            context = multiprocessing.get_context("spawn")
            with (
                context.Manager() as manager,
                ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool,
            ):
                events = manager.Queue()
                futures = {
                    pool.submit(
                        make_scene,
                        args.out,
                        preset.name,
                        args.seed,
                        index,
                        count,
                        report=ProgressEvents(events),
                        threads=threads,
                        **options,
                    ): index
                    for index in indices
                }
                pending = dict(futures)
                while pending:
                    with contextlib.suppress(queues.Empty):
                        progress.update(*events.get(timeout=0.5))
                    for future in [f for f in pending if f.done()]:
                        index = pending.pop(future)
                        progress.finish(index)
                        print(future.result(), flush=True)
    finally:
        progress.close()
    print(f"{len(indices)} scene(s) in {args.out} ({time.perf_counter() - start:.1f} s, {jobs} job(s))")
    return 0
