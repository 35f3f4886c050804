"""Issue 40: ``prepare``'s fit iterations are declared once, by the 3DGS fit configuration.

``--fit-iterations``' help reads ``FitConfig.iterations`` from the source (``--help`` may not import torch),
``PrepareSettings`` and ``FitSource`` default to it, and a ``prepare(...)`` keyword is a settings field.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from setdiff_bench.cli import prepare as prepare_cli
from setdiff_bench.cli.declared import declared_field_default
from setdiff_bench.cli.prepare import FIT_CONFIG
from setdiff_bench.gaussians.fit import FitConfig
from setdiff_bench.packets.fits import DEFAULT_FIT_ITERATIONS, FitSource
from setdiff_bench.packets.prepare_settings import PrepareSettings


def test_the_declared_default_is_the_fit_configurations() -> None:
    assert declared_field_default(*FIT_CONFIG, "iterations") == FitConfig().iterations
    assert FitConfig().iterations == DEFAULT_FIT_ITERATIONS
    assert PrepareSettings().fit_iterations == FitConfig().iterations
    assert FitSource(fits_dir=Path("."), fit=False, out=Path(".")).fit_iterations == FitConfig().iterations


def test_the_help_names_it() -> None:
    parser = argparse.ArgumentParser()
    prepare_cli.add_arguments(parser)
    (action,) = [a for a in parser._actions if "--fit-iterations" in a.option_strings]
    assert action.default is None  # None: with --fit-preset, the preset's own schedule
    assert f"(default {FitConfig().iterations}; with --fit-preset" in str(action.help)


def test_declared_field_default_follows_a_re_export(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "face_mod.py").write_text(
        "from setdiff_bench.gaussians.fit import FitConfig\n", encoding="utf-8"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert declared_field_default("face_mod", "FitConfig", "iterations") == FitConfig().iterations
    package = tmp_path / "face_pkg"
    package.mkdir()
    (package / "__init__.py").write_text("from .config import Settings\n", encoding="utf-8")
    (package / "config.py").write_text("class Settings:\n    iterations: int = 7\n", encoding="utf-8")
    (package / "face.py").write_text("from .config import Settings\n", encoding="utf-8")
    assert declared_field_default("face_pkg", "Settings", "iterations") == 7
    assert declared_field_default("face_pkg.face", "Settings", "iterations") == 7
    with pytest.raises(LookupError):
        declared_field_default(*FIT_CONFIG, "no_such_field")
    with pytest.raises(LookupError):
        declared_field_default("face_mod", "NoSuchClass", "iterations")


def test_prepare_keywords_are_settings_fields() -> None:
    from setdiff_bench.packets.prepare import prepare

    with pytest.raises(TypeError):
        prepare("synthetic", ".", ".", no_such_option=1)
