"""The demo's stages declared as data: every ``setdiff-bench`` command the demo runs, in order, built from
one :class:`DemoPlan` (preset, benchmark, folders, seed, jobs, device, train or shipped models) before
anything runs.

:func:`demo_stages` gives them as a :class:`DemoStages` table: ``setup`` (synth, prepare, and with
``--train`` one ``train`` per learned method), ``runs`` (one ``run`` per method of :data:`METHODS`, which
:func:`setdiff_bench.pipeline.demo.run_demo` may run in two lanes), ``leaderboard`` and, on request,
``ablations``.  Each :class:`DemoStage` is ``(name, argv)``: the name the ledger and the report use and the
arguments after ``setdiff-bench`` (numbers are passed as text by :class:`~setdiff_bench.pipeline.stages.Pipeline`).

With ``--refit`` (:class:`~setdiff_bench.pipeline.presets.RefitDemo`) the store holds only the scored groups, every
run scores the warp error where the scenes have timestamps, and two more tables follow the runs: ``refits``
(per enhancer ``X``: one ``refit`` per test scene and refitted group, with snapshots, then the packets of its
refit scenes and of each snapshot, scored as ``X-3D``, ``X-3D+`` and ``X-3D-NNNNNN``) and ``compares`` (the
paired gains docs/refit.md reads the rows by).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

from setdiff_bench.io.refit_layout import snapshot_folder
from setdiff_bench.pipeline.demo._layout import DemoPaths
from setdiff_bench.pipeline.presets import DemoBenchmark, DemoPreset
from setdiff_bench.pipeline.stages import relative
from setdiff_bench.refit.settings import RefitSettings

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
        refit: ``demo --refit``: score every enhancer as ``X``, ``X 3D`` and ``X 3D+`` (module docstring).
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
    refit: bool = False

    def rel(self, path: Path) -> str:
        """``path`` as the commands name it: relative to :attr:`base` when inside it."""
        return relative(path, self.base)

    @property
    def quiet(self) -> list[str]:
        """``--no-progress`` when progress bars are off (for the verbs that take it)."""
        return [] if self.progress else ["--no-progress"]

    @property
    def test_scenes(self) -> list[str]:
        """The test scenes' names."""
        return [self.scene_name(self.seed, index) for index in self.test_indices]

    @property
    def device_flag(self) -> list[str]:
        """``--device D`` when the demo was given one."""
        return ["--device", self.device] if self.device else []

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
    #: ``demo --refit``: per enhancer, its refits and then the stages that score them, in order
    refits: dict[str, list[DemoStage]] = dataclasses.field(default_factory=dict)
    compares: list[DemoStage] = dataclasses.field(default_factory=list)


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
    prepare += _declared_test_scenes(plan)
    if plan.refit:
        prepare += [part for group in benchmark.refit.scored for part in ("--group", group)]
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
        run += plan.device_flag + _warp(plan)
        runs.append(DemoStage(f"run {method}", run + plan.quiet))
    return runs


def _warp(plan: DemoPlan) -> list[str]:
    """``--warp on`` for the runs of ``demo --refit`` on a benchmark whose frames carry timestamps."""
    return ["--warp", "on"] if plan.refit and plan.benchmark.refit.warp else []


def _declared_test_scenes(plan: DemoPlan) -> list[str]:
    """``--test-scene`` for each test scene when only the test scenes exist (the shipped-model demo of a benchmark
    without a packaged protocol: the synthetic protocol's interleaved split over them would differ); every
    ``prepare`` and ``refit`` of the demo takes them, so that a refit's packets have the shape and references of
    the packets it is scored on."""
    if plan.train or plan.benchmark.protocol is not None:
        return []
    return [part for scene in plan.test_scenes for part in ("--test-scene", scene)]


def _scene_source(plan: DemoPlan) -> list[Any]:
    """The dataset, protocol and root every ``prepare`` / ``refit`` of the demo reads the scenes with."""
    protocol = ["--protocol", plan.benchmark.protocol] if plan.benchmark.protocol else []
    return [plan.benchmark.dataset, *protocol, "--root", plan.rel(plan.paths.scenes)]


def refit_steps(plan: DemoPlan) -> list[int]:
    """The refit steps the rows are scored at: every snapshot and the refit's last step (progressive preset)."""
    every = plan.benchmark.refit.snapshot_every
    return RefitSettings.preset("progressive", snapshot_every=every).snapshot_steps()


def refit_stages(plan: DemoPlan, method: str) -> list[DemoStage]:
    """``demo --refit``: one progressive ``refit`` with ``method`` per test scene and refitted group."""
    checkpoints, refit = plan.checkpoints, plan.benchmark.refit
    stages = []
    for scene in plan.test_scenes:
        for group in refit.groups:
            command = [
                "refit",
                *_scene_source(plan),
                "--scene",
                scene,
                "--fits",
                plan.rel(plan.paths.scenes),
                *_declared_test_scenes(plan),
            ]
            command += ["--group", group, "--method", method]
            command += ["--checkpoint", checkpoints[method]] if method in checkpoints else []
            command += [
                "--snapshot-every",
                refit.snapshot_every,
                "--out",
                plan.rel(plan.paths.refits(method)),
            ]
            stages.append(
                DemoStage(f"refit {method} {scene} {group}", command + plan.device_flag + plan.quiet)
            )
    return stages


def refit_rows(plan: DemoPlan) -> list[str]:
    """The leaderboard's rows under ``demo --refit``, in table order: per enhancer ``X``, ``X-3D``, ``X-3D+``
    (not for ``identity``) and ``X-3D-NNNNNN`` at each snapshot."""
    steps = refit_steps(plan)
    rows = []
    for method in METHODS:
        rows += [method, f"{method}-3D"] + ([f"{method}-3D+"] if method != "identity" else [])
        rows += [f"{method}-3D-{step:06d}" for step in steps[:-1]]
    return rows


def refit_scoring_stages(plan: DemoPlan, method: str) -> list[DemoStage]:
    """``demo --refit``: the packets of ``method``'s refit scenes (and of each snapshot) and their runs."""
    checkpoints, steps = plan.checkpoints, refit_steps(plan)
    stages = []
    out = plan.paths.refits(method)
    for step in steps:
        last = step == steps[-1]
        name = f"{method}-3D" if last else f"{method}-3D-{step:06d}"
        fits = plan.rel(out if last else snapshot_folder(out, step))
        packets = plan.rel(plan.paths.refit_packets(name))
        prepare = ["prepare", *_scene_source(plan), "--fits", fits, "--out", packets, "--split", "test"]
        prepare += _declared_test_scenes(plan)
        prepare += [part for group in plan.benchmark.refit.scored for part in ("--group", group)]
        prepare += ["--workers", plan.jobs]
        stages.append(DemoStage(f"prepare {name}", prepare + plan.quiet))
        scored = [("identity", name)]
        scored += [(method, f"{method}-3D+")] if last and method != "identity" else []
        for enhancer, row in scored:
            run = ["run", "--method", enhancer, "--name", row, "--packets", packets, "--split", "test"]
            run += ["--out", plan.rel(plan.paths.runs / row), "--refit", fits]
            run += ["--checkpoint", checkpoints[enhancer]] if enhancer in checkpoints else []
            stages.append(DemoStage(f"run {row}", run + plan.device_flag + _warp(plan) + plan.quiet))
    return stages


#: The paired comparisons ``demo --refit`` writes (``compare A B``), by enhancer ``X``: what the refit adds
#: over its own schedule, what post-processing the refit render adds, refit against post-process, and the
#: last pair of X / X 3D / X 3D+ (so the report can say which of the three the intervals show winning).
REFIT_COMPARISONS = (
    ("{x}-3D", "identity-3D"),
    ("{x}-3D+", "{x}"),
    ("{x}-3D", "{x}"),
    ("{x}-3D+", "{x}-3D"),
)


def compare_stages(plan: DemoPlan) -> list[DemoStage]:
    """``demo --refit``: ``identity-3D`` against ``identity`` (the schedule alone), then
    :data:`REFIT_COMPARISONS` for every other enhancer, into ``<out>``."""
    pairs = [("identity-3D", "identity")]
    pairs += [
        (a.format(x=m), b.format(x=m)) for m in METHODS if m != "identity" for a, b in REFIT_COMPARISONS
    ]
    runs, out = plan.rel(plan.paths.runs), plan.rel(plan.paths.out)
    return [DemoStage(f"compare {a} {b}", ["compare", a, b, "--runs", runs, "--out", out]) for a, b in pairs]


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
            ",".join(refit_rows(plan) if plan.refit else METHODS),
            *(["--cost"] if plan.refit else []),
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
        refits={m: refit_stages(plan, m) + refit_scoring_stages(plan, m) for m in METHODS}
        if plan.refit
        else {},
        compares=compare_stages(plan) if plan.refit else [],
    )
