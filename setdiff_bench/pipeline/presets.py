"""The demo's benchmarks, their presets and the default output folder (:mod:`setdiff_bench.pipeline.demo`),
apart from the demo so that ``setdiff-bench demo --help`` lists them without importing pandas or torch.

Two embedded benchmarks, declared as data (:class:`DemoBenchmark`):

* ``driving`` (the default): lane shifts of a recorded street drive, the synthetic protocol, EUVS layout;
  the verdict group is +2 lanes.
* ``sparse``: DL3DV-style handheld walks around a plaza, the packaged ``dl3dv_sparse_synthetic`` protocol
  (3DGS fitted on 3 / 6 / 9 views), the leaderboard in Table 4's layout beside the paper's reported rows;
  the verdict group is 3 views.
"""

from __future__ import annotations

from dataclasses import dataclass

from setdiff_bench.errors import UsageError


@dataclass(frozen=True)
class DemoPreset:
    """What one demo preset runs.

    Attributes:
        name, description: the preset key and one line for ``--help``.
        synth_preset: the ``setdiff-bench synth`` preset (scene count, size, fit schedule).
        scenes: number of scenes (``None``: the synth preset's).
        setdiff_config, difix_config: training configs (TOML paths or packaged names).
        setdiff_steps, difix_steps: optimiser steps.
        grid_frames: targets shown in the qualitative grid.
        benchmark: the :class:`DemoBenchmark` this preset belongs to.
    """

    name: str
    description: str
    synth_preset: str
    scenes: int | None
    setdiff_config: str
    difix_config: str
    setdiff_steps: int
    difix_steps: int
    grid_frames: int
    benchmark: str = "driving"


DEMO_PRESETS: dict[str, DemoPreset] = {
    "tiny": DemoPreset(
        "tiny",
        "smoke test: tiny 80x48 scenes (with --train: 3 scenes, a few steps)",
        "tiny",
        3,
        "tiny_setdiff",
        "tiny_difix",
        20,
        20,
        2,
    ),
    "default": DemoPreset(
        "default",
        "the 2 test scenes at 256x144 with the shipped models (about 5 minutes "
        "on 2 CPU cores); with --train all 6 scenes and short CPU training",
        "default",
        None,
        "tiny_setdiff",
        "tiny_difix",
        230,
        200,
        6,
    ),
    "full": DemoPreset(
        "full",
        "8 scenes at 512x288; with --train long training, for a GPU",
        "large",
        None,
        "tiny_setdiff",
        "tiny_difix",
        20000,
        20000,
        8,
    ),
}


#: The sparse-view benchmark's presets, under the same names as the driving ones.
SPARSE_DEMO_PRESETS: dict[str, DemoPreset] = {
    "tiny": DemoPreset(
        "tiny",
        "smoke test: tiny 64x40 walks (with --train: 3 scenes, a few steps)",
        "sparse_tiny",
        3,
        "tiny_setdiff",
        "tiny_difix",
        20,
        20,
        2,
        "sparse",
    ),
    "default": DemoPreset(
        "default",
        "the 2 test walks at 256x144 with the shipped sparse models; with --train 10 walks and short "
        "CPU training",
        "sparse",
        10,
        "tiny_setdiff",
        "tiny_difix",
        2250,
        2250,
        6,
        "sparse",
    ),
    "full": DemoPreset(
        "full",
        "12 walks at 512x288; with --train long training, for a GPU",
        "sparse_large",
        None,
        "tiny_setdiff",
        "tiny_difix",
        20000,
        20000,
        8,
        "sparse",
    ),
}


@dataclass(frozen=True)
class RefitDemo:
    """What ``demo --refit`` does on a benchmark: every enhancer as ``X``, ``X 3D`` and ``X 3D+`` (docs/refit.md).

    Attributes:
        groups: the protocol groups whose targets each test scene's fits are refitted on (one refit per scene,
            group and enhancer; the groups' fits must differ).
        scored: the groups the rows are scored on (the refitted ones and, where the benchmark has them,
            held-out frames of the fit's own trajectory).
        warp: score the warp error of each camera sequence (the scenes' frames carry timestamps).
        snapshot_every: refit steps between the snapshots the refit-steps plot is drawn from.
        default_out, published: the demo's scratch folder and the folder under ``results/`` it is published to.
    """

    groups: tuple[str, ...]
    scored: tuple[str, ...]
    warp: bool
    snapshot_every: int
    default_out: str
    published: str


@dataclass(frozen=True)
class DemoBenchmark:
    """One embedded benchmark the demo runs end to end.

    Attributes:
        name, description: the ``--benchmark`` key and one line for ``--help``.
        dataset: the ``prepare`` dataset key the scenes are read as (their on-disk layout).
        protocol: the packaged protocol ``prepare`` applies (``None``: the dataset's own).
        leaderboard: the ``leaderboard --dataset`` key (its table layout and plots).
        with_reported: whether the leaderboard adds the paper's reported rows of that dataset.
        shipped: ``{method: packaged model}`` evaluated unless ``--train``.
        verdict_group, verdict_key, verdict_title: the group the summary's verdict is taken on, its key
            in ``demo.json`` and its heading in the report.
        title: the report's title.
        presets: the benchmark's presets by name.
        default_out: where the demo writes unless ``--out`` says otherwise: a git-ignored scratch folder of
            its own (two benchmarks never share a store), never the published results.
        published: the folder under ``results/`` holding the published run (compared by
            :mod:`setdiff_bench.pipeline.reproduction`).
        tolerance: ``{metric: largest cell difference}`` to expect from another CPU instruction set or
            thread count, measured (docs/reproducibility.md, "Across CPUs").
        note: a paragraph the report puts under the leaderboard (what the table can and cannot say).
        refit: what ``demo --refit`` runs on this benchmark.
    """

    name: str
    description: str
    dataset: str
    protocol: str | None
    leaderboard: str
    with_reported: bool
    shipped: dict[str, str]
    verdict_group: str
    verdict_key: str
    verdict_title: str
    title: str
    presets: dict[str, DemoPreset]
    default_out: str
    published: str
    tolerance: dict[str, float]
    refit: RefitDemo
    note: str = ""


#: Largest leaderboard-cell difference measured between CPU instruction sets (ATen default / AVX2 / AVX-512,
#: oneDNN SSE4.1) and thread counts for the published runs, rounded up (docs/reproducibility.md).  Scenes,
#: fits and packets are byte-identical across them; the enhancers' inference and the metrics' kernels
#: differ in the last bits, which move a few 8-bit output pixels.
DRIVING_TOLERANCE = {"psnr": 0.01, "ssim": 0.0001, "lpips": 0.0001}
SPARSE_TOLERANCE = {"psnr": 0.01, "ssim": 0.0001, "lpips": 0.0001}

DEMO_BENCHMARKS: dict[str, DemoBenchmark] = {
    "driving": DemoBenchmark(
        name="driving",
        description="lane shifts of synthetic street drives (EUVS layout, synthetic protocol)",
        dataset="synthetic",
        protocol=None,
        leaderboard="synthetic",
        with_reported=False,
        shipped={"setdiff": "tiny_setdiff", "difix": "tiny_difix"},
        verdict_group="lane+2",
        verdict_key="lane_plus_2",
        verdict_title="At +2 lanes",
        title="Synthetic benchmark: SetDiff against the baselines",
        presets=DEMO_PRESETS,
        default_out="runs/demo",
        published="synthetic",
        tolerance=DRIVING_TOLERANCE,
        # the refit distils +2 lanes (Difix3D+'s driving setting); the held-out lane-0 frames show what the
        # refit does to the recorded trajectory
        refit=RefitDemo(("lane+2",), ("lane+2", "interp"), True, 100, "runs/demo_refit", "synthetic_refit"),
    ),
    "sparse": DemoBenchmark(
        name="sparse",
        description="sparse-view handheld walks (DL3DV layout, protocol dl3dv_sparse_synthetic: 3DGS on "
        "3 / 6 / 9 views, paper Table 4)",
        dataset="dl3dv",
        protocol="dl3dv_sparse_synthetic",
        leaderboard="dl3dv",
        with_reported=True,
        shipped={"setdiff": "tiny_setdiff_sparse", "difix": "tiny_difix_sparse"},
        verdict_group="n3",
        verdict_key="views_3",
        verdict_title="At 3 views",
        title="Sparse-view synthetic benchmark: SetDiff against the baselines",
        presets=SPARSE_DEMO_PRESETS,
        default_out="runs/demo_sparse",
        published="synthetic_sparse",
        tolerance=SPARSE_TOLERANCE,
        # one refit per view count (each its own fit); the walks carry no timestamps, so no warp error
        refit=RefitDemo(
            ("n3", "n6", "n9"),
            ("n3", "n6", "n9"),
            False,
            100,
            "runs/demo_sparse_refit",
            "synthetic_sparse_refit",
        ),
        note="The (paper) rows are the paper's Table 4 on real DL3DV captures, where 3DGS fitted on 3 views "
        "renders at 10.97 dB; this benchmark's synthetic renders are far less damaged (see the identity row), "
        "so the rows show the layout and the paper's gaps, not numbers to compare with ours.",
    ),
}
DEFAULT_BENCHMARK = "driving"


def get_benchmark(name: str) -> DemoBenchmark:
    """The demo benchmark called ``name``; :class:`UsageError` listing the choices otherwise."""
    if name not in DEMO_BENCHMARKS:
        raise UsageError(
            f"unknown demo benchmark {name!r}; choose one of {', '.join(DEMO_BENCHMARKS)}", "--benchmark"
        )
    return DEMO_BENCHMARKS[name]


def get_demo_preset(name: str, benchmark: str = DEFAULT_BENCHMARK) -> DemoPreset:
    """Preset ``name`` of ``benchmark``; :class:`UsageError` listing the choices otherwise."""
    presets = get_benchmark(benchmark).presets
    if name not in presets:
        raise UsageError(f"unknown demo preset {name!r}; choose one of {', '.join(presets)}", "--preset")
    return presets[name]
