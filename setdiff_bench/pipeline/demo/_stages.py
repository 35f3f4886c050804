"""The demo's stages declared as data: every ``setdiff-bench`` command the demo runs, in order, built from
one :class:`DemoPlan` (preset, benchmark, folders, seed, jobs, device, train or shipped models) before
anything runs.

:func:`demo_stages` gives them as a :class:`DemoStages` table: ``setup`` (synth, prepare, and with
``--train`` one ``train`` per learned method), ``runs`` (one ``run`` per method of :data:`METHODS`, which
:func:`setdiff_bench.pipeline.demo.run_demo` may run in two lanes), ``leaderboard`` and, on request,
``ablations``.  Each :class:`DemoStage` is ``(name, argv)``: the name the ledger and the report use and the
arguments after ``setdiff-bench`` (numbers are passed as text by :class:`~setdiff_bench.pipeline.stages.Pipeline`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from setdiff_bench.pipeline.demo._layout import DemoPaths
from setdiff_bench.pipeline.presets import DemoBenchmark, DemoPreset
from setdiff_bench.pipeline.stages import relative

#: The methods every demo runs and tabulates, in table order.
METHODS = ("identity", "reproject", "difix", "setdiff")


class DemoStage(NamedTuple):
    """One stage: its name (ledger, report, progress lines) and its argv after ``setdiff-bench``."""

    name: str
    argv: list[Any]


@dataclass(frozen=True)
class DemoPlan:
    """What the demo's commands are made of.

    Attributes:
        base: the working directory the commands run in (paths in them are relative to it when inside).
        test_indices: generator indices of the preset's test scenes (``(seed, index)`` names them).
        scene_name: ``(seed, index) → scene name`` of the benchmark's scenes.
        steps, configs: training steps and config per learned method (``setdiff``, ``difix``).
    """

    preset: DemoPreset
    benchmark: DemoBenchmark
    paths: DemoPaths
    base: Path
    seed: int
    jobs: int
    device: str | None
    train: bool
    progress: bool
    test_indices: list[int]
    scene_name: Callable[[int, int], str]
    steps: dict[str, int]
    configs: dict[str, str]

    def rel(self, path: Path) -> str:
        """``path`` as the commands name it: relative to :attr:`base` when inside it."""
        return relative(path, self.base)

    @property
    def quiet(self) -> list[str]:
        """``--no-progress`` when progress bars are off (for the verbs that take it)."""
        return [] if self.progress else ["--no-progress"]

    @property
    def checkpoints(self) -> dict[str, str]:
        """Method → checkpoint: trained by this demo (``<work>/checkpoints/<method>``), else the shipped
        models."""
        return (
            {method: self.rel(self.paths.checkpoints(method)) for method in self.configs}
            if self.train
            else dict(self.benchmark.shipped)
        )


@dataclass(frozen=True)
class DemoStages:
    """The demo's stages in the order they run (module docstring)."""

    setup: list[DemoStage]
    runs: list[DemoStage]
    leaderboard: DemoStage
    ablations: list[DemoStage]


def synth_stage(plan: DemoPlan) -> DemoStage:
    """Generate and fit the scenes: every scene with ``--train``, else only the test scenes."""
    rel, preset = plan.rel, plan.preset
    synth = [
        "synth",
        "--out",
        rel(plan.paths.scenes),
        "--preset",
        preset.synth_preset,
        "--seed",
        plan.seed,
        "--jobs",
        plan.jobs,
    ]
    if plan.train:
        synth += ["--scenes", preset.scenes] if preset.scenes else []
    else:
        synth += ["--indices", ",".join(str(i) for i in plan.test_indices)]
    synth += ["--device", plan.device] if plan.device else []
    return DemoStage("synth", synth + plan.quiet)


def prepare_stage(plan: DemoPlan) -> DemoStage:
    """Cut the scenes into packets (every split with ``--train``, else the test split)."""
    rel, benchmark = plan.rel, plan.benchmark
    prepare = [
        "prepare",
        benchmark.dataset,
        *(["--protocol", benchmark.protocol] if benchmark.protocol else []),
        "--root",
        rel(plan.paths.scenes),
        "--fits",
        rel(plan.paths.scenes),
        "--out",
        rel(plan.paths.packets),
        "--split",
        "all" if plan.train else "test",
        "--workers",
        plan.jobs,
    ]
    if not plan.train and benchmark.protocol is None:
        # only the test scenes exist here: the synthetic protocol's interleaved split over them would differ
        prepare += [
            part
            for index in plan.test_indices
            for part in ("--test-scene", plan.scene_name(plan.seed, index))
        ]
    return DemoStage("prepare", prepare + plan.quiet)


def train_stages(plan: DemoPlan) -> list[DemoStage]:
    """With ``--train``: one ``train`` per learned method on the packets; else none."""
    stages = []
    for method in plan.configs if plan.train else ():
        command = [
            "train",
            "--config",
            plan.configs[method],
            "--packets",
            plan.rel(plan.paths.packets),
            "--out",
            plan.checkpoints[method],
            "--steps",
            plan.steps[method],
            "--seed",
            plan.seed,
        ]
        command += ["--device", "cpu"] if plan.device == "cpu" else []
        stages.append(DemoStage(f"train {method}", command + plan.quiet))
    return stages


def run_stages(plan: DemoPlan) -> list[DemoStage]:
    """One ``run`` per method of :data:`METHODS` on the test split (learned ones with their checkpoint)."""
    checkpoints = plan.checkpoints
    runs = []
    for method in METHODS:
        run = [
            "run",
            "--method",
            method,
            "--packets",
            plan.rel(plan.paths.packets),
            "--split",
            "test",
            "--out",
            plan.rel(plan.paths.runs / method),
        ]
        run += ["--checkpoint", checkpoints[method]] if method in checkpoints else []
        run += ["--device", plan.device] if plan.device else []
        runs.append(DemoStage(f"run {method}", run + plan.quiet))
    return runs


def leaderboard_stage(plan: DemoPlan) -> DemoStage:
    """The benchmark's leaderboard of the four runs, with plots, grids and (if the benchmark says so) the
    paper's reported rows."""
    rel, benchmark = plan.rel, plan.benchmark
    return DemoStage(
        "leaderboard",
        [
            "leaderboard",
            "--dataset",
            benchmark.leaderboard,
            "--runs",
            rel(plan.paths.runs),
            "--out",
            rel(plan.paths.out),
            "--methods",
            ",".join(METHODS),
            "--plots",
            "--grids",
            plan.preset.grid_frames,
            "--packets",
            rel(plan.paths.packets),
            *(["--with-reported"] if benchmark.with_reported else []),
        ],
    )


def ablation_stages(plan: DemoPlan) -> list[DemoStage]:
    """The geometry and set-size ablations of SetDiff (they need ``--train``)."""
    rel = plan.rel
    ablate_common = [
        "--packets",
        rel(plan.paths.packets),
        "--out",
        rel(plan.paths.out),
        "--work",
        rel(plan.paths.work),
        *plan.quiet,
    ]
    ablate_common += ["--device", plan.device] if plan.device else []
    return [
        DemoStage(
            "ablate geometry",
            [
                "ablate",
                "geometry",
                "--config",
                plan.configs["setdiff"],
                "--steps",
                plan.steps["setdiff"],
                *ablate_common,
            ],
        ),
        DemoStage(
            "ablate setsize",
            ["ablate", "setsize", "--checkpoint", rel(plan.paths.checkpoints("setdiff")), *ablate_common],
        ),
    ]


def demo_stages(plan: DemoPlan, *, ablations: bool = False) -> DemoStages:
    """Every stage of the demo ``plan`` describes, in order (``ablations``: add the two ablations)."""
    return DemoStages(
        setup=[synth_stage(plan), prepare_stage(plan), *train_stages(plan)],
        runs=run_stages(plan),
        leaderboard=leaderboard_stage(plan),
        ablations=ablation_stages(plan) if ablations else [],
    )
