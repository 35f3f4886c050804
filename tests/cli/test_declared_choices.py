"""Issue 40: CLI choices that name a library table are read from it (declared once)."""

from __future__ import annotations

import argparse
from typing import get_args

import pytest

from setdiff_bench.cli import fit, leaderboard, serve, synth, weights
from setdiff_bench.cli.declared import declared_value, module_source, registry_names
from setdiff_bench.metrics.lpips_arch import NETS
from setdiff_bench.models.setdiff.config import ModelConfig
from setdiff_bench.models.setdiff.methods import Method
from setdiff_bench.protocols.profiles import DEFAULT_PROFILE
from setdiff_bench.reporting.leaderboard import FORMATS
from setdiff_bench.synthetic.presets import PRESETS
from setdiff_bench.synthetic.sparse import SPARSE_PRESETS


def option(module: object, flag: str, *words: str) -> argparse.Action:
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)  # type: ignore[attr-defined]
    if words:  # a sub-command's option
        (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        parser = sub.choices[words[0]]
    (action,) = [a for a in parser._actions if flag in a.option_strings]
    return action


def choices(module: object, flag: str, *words: str) -> tuple[str, ...]:
    return tuple(option(module, flag, *words).choices)


def test_registry_names_are_the_imported_registries_keys() -> None:
    assert registry_names("setdiff_bench.synthetic.presets", "PRESETS") == tuple(PRESETS)
    assert registry_names("setdiff_bench.synthetic.sparse._sparse", "SPARSE_PRESETS") == tuple(SPARSE_PRESETS)


def test_declared_values_are_the_imported_ones() -> None:
    assert declared_value("setdiff_bench.reporting.leaderboard.render", "FORMATS") == FORMATS
    assert declared_value("setdiff_bench.protocols.profiles", "DEFAULT_PROFILE") == DEFAULT_PROFILE
    assert declared_value("setdiff_bench.metrics.lpips_arch", "NETS") == NETS


def test_module_source_and_refusals() -> None:
    assert module_source("setdiff_bench.reporting.leaderboard.render").name == "render.py"
    assert module_source("setdiff_bench.protocols.parser").name == "parser.py"  # a package mapped elsewhere
    with pytest.raises(LookupError):
        registry_names("setdiff_bench.synthetic.presets", "get_preset")
    with pytest.raises(LookupError):
        declared_value("setdiff_bench.synthetic.presets", "PRESETS")  # calls, not a literal
    with pytest.raises(LookupError):
        module_source("setdiff_bench.no_such_module")


def test_cli_choices_come_from_the_library() -> None:
    assert choices(synth, "--preset") == (*PRESETS, *SPARSE_PRESETS)
    assert choices(fit, "--preset") == (*PRESETS, "standard")
    assert choices(serve, "--method") == get_args(Method)
    assert ModelConfig.__dataclass_fields__["method"].type in ("Method", Method)
    assert option(leaderboard, "--format").default == ",".join(FORMATS)
    assert option(leaderboard, "--profile").default == DEFAULT_PROFILE
    assert choices(weights, "--net", "lpips") == (*NETS, "all")


def test_run_and_prepare_choices_and_defaults_are_the_settings_dataclasses() -> None:
    """``run --warp/--flow/--batch-size`` and ``prepare --split/--cmap-precision`` show what RunSettings and
    PrepareSettings declare (read from their sources, so ``--help`` imports no torch)."""
    from setdiff_bench.cli import prepare, run
    from setdiff_bench.cli.declared import declared_literal
    from setdiff_bench.evaluation.run import RunSettings, WarpMode
    from setdiff_bench.metrics.optical_flow import FLOW_METHODS, FlowMethod
    from setdiff_bench.packets.prepare_settings import SPLIT_CHOICES, CmapPrecision, PrepareSettings

    settings = RunSettings(method="identity")
    assert choices(run, "--warp") == get_args(WarpMode) == ("auto", "on", "off")
    assert option(run, "--warp").default == settings.warp
    assert choices(run, "--flow") == get_args(FlowMethod) == FLOW_METHODS == ("deepflow", "dis")
    assert option(run, "--flow").default == settings.flow_method
    assert option(run, "--batch-size").default == settings.batch_size == 8
    defaults = PrepareSettings()
    assert (
        choices(prepare, "--split") == SPLIT_CHOICES and option(prepare, "--split").default == defaults.split
    )
    assert choices(prepare, "--cmap-precision") == get_args(CmapPrecision) == ("float32", "half")
    assert option(prepare, "--cmap-precision").default == defaults.cmap_precision
    with pytest.raises(LookupError, match="not a Literal"):
        declared_literal("setdiff_bench.packets.prepare_settings", "SPLIT_CHOICES")


def test_fit_init_and_render_backend_choices_are_the_library_literals() -> None:
    from setdiff_bench.cli import fit, prepare, render
    from setdiff_bench.gaussians.fit import INIT_MODES, InitMode
    from setdiff_bench.gaussians.render import Backend

    assert (
        choices(fit, "--init")
        == get_args(InitMode)
        == INIT_MODES
        == ("auto", "sparse", "triangulate", "random")
    )
    assert choices(render, "--backend") == get_args(Backend) == ("torch", "gsplat")
    assert choices(prepare, "--backend") == ("auto", *get_args(Backend))
