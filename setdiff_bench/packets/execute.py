"""Running packet jobs: in this process, or in a pool of spawned worker processes (``prepare --workers K``).

With one worker (or one job) every job is built here; otherwise the jobs are cut into about ``4 × workers``
batches, each built by one spawned process (:func:`setdiff_bench.packets.worker.build_many`, torch threads
set by :func:`~setdiff_bench.packets.worker.init_worker`).  A worker's error is raised here after the
running batches finish and the queued ones are dropped.  Stats come back per packet as each batch ends.
"""

from __future__ import annotations

import math
import multiprocessing
from collections.abc import Iterable, Sequence
from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait
from pathlib import Path

from setdiff_bench.packets.jobs import PacketJob
from setdiff_bench.packets.worker import JobStats, build_many, build_packet, init_worker


def execute(
    jobs: Sequence[PacketJob],
    root: Path,
    backend: str,
    device: str,
    workers: int,
    threads: int,
    progress: bool,
) -> Iterable[JobStats]:
    from tqdm.auto import tqdm

    bar = tqdm(
        total=len(jobs),
        desc="prepare",
        unit="packet",
        disable=True if not progress or not jobs else None,
        dynamic_ncols=True,
    )  # None: tqdm hides itself when stderr is not a terminal
    try:
        if workers == 1 or len(jobs) <= 1:
            for job in jobs:
                stats = build_packet(job, root, backend, device)
                bar.update(1)
                yield stats
            return
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(
            max_workers=min(workers, len(jobs)),
            mp_context=context,
            initializer=init_worker,
            initargs=(threads,),
        ) as pool:
            chunk = math.ceil(len(jobs) / (4 * workers))
            futures = [
                pool.submit(build_many, jobs[i : i + chunk], root, backend, device)
                for i in range(0, len(jobs), chunk)
            ]
            pending = set(futures)
            try:
                while pending:
                    done, pending = wait(pending, return_when=FIRST_EXCEPTION)
                    for future in done:
                        for stats in future.result():  # re-raises a worker's error here
                            bar.update(1)
                            yield stats
            except BaseException:
                pool.shutdown(wait=True, cancel_futures=True)  # finish running batches, drop queued ones
                raise
    finally:
        bar.close()
