"""The demo's presets and default output folder (:mod:`setdiff_bench.pipeline.demo`), apart from the demo
so that ``setdiff-bench demo --help`` lists them without importing pandas or torch."""

from __future__ import annotations

from dataclasses import dataclass

from setdiff_bench.errors import UsageError

#: Where the demo writes unless told otherwise: a scratch folder, git-ignored, never the published results.
DEFAULT_OUT = "runs/demo"


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


def get_demo_preset(name: str) -> DemoPreset:
    if name not in DEMO_PRESETS:
        raise UsageError(f"unknown demo preset {name!r}; choose one of {', '.join(DEMO_PRESETS)}", "--preset")
    return DEMO_PRESETS[name]
