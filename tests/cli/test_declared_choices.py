"""Issue 40: CLI choices that name a library table are read from it (declared once)."""

from __future__ import annotations

import argparse
from typing import get_args

import pytest

from setdiff_bench.cli import fit, serve, synth
from setdiff_bench.cli.declared import registry_names
from setdiff_bench.models.setdiff.config import ModelConfig
from setdiff_bench.models.setdiff.methods import Method
from setdiff_bench.synthetic.presets import PRESETS
from setdiff_bench.synthetic.sparse import SPARSE_PRESETS


def choices(module: object, flag: str) -> tuple[str, ...]:
    parser = argparse.ArgumentParser()
    module.add_arguments(parser)  # type: ignore[attr-defined]
    (action,) = [a for a in parser._actions if flag in a.option_strings]
    return tuple(action.choices)


def test_registry_names_are_the_imported_registries_keys() -> None:
    assert registry_names("setdiff_bench.synthetic.presets", "PRESETS") == tuple(PRESETS)
    assert registry_names("setdiff_bench.synthetic.sparse", "SPARSE_PRESETS") == tuple(SPARSE_PRESETS)


def test_registry_names_refuses_what_is_not_a_dict_literal() -> None:
    with pytest.raises(LookupError):
        registry_names("setdiff_bench.synthetic.presets", "get_preset")


def test_cli_choices_come_from_the_library() -> None:
    assert choices(synth, "--preset") == (*PRESETS, *SPARSE_PRESETS)
    assert choices(fit, "--preset") == (*PRESETS, "standard")
    assert choices(serve, "--method") == get_args(Method)
    assert ModelConfig.__dataclass_fields__["method"].type in ("Method", Method)
