"""The method registry: built-ins as lazy data, entry-point plugins, option checks, `list methods`."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.base import (
    BUILTIN_METHODS,
    Enhancer,
    MethodSpec,
    RegistryWarning,
    available_methods,
    create_enhancer,
    register_builtin,
)
from setdiff_bench.enhancers.identity import IdentityEnhancer
from setdiff_bench.errors import UsageError
from tests.enhancers.plugin_fixtures import install_plugin
from tests.evaluation.run.store_fixtures import camera_at, plane_view


def test_builtins_are_listed_without_importing_model_code() -> None:
    code = (
        "import sys; from setdiff_bench.enhancers.base import available_methods; m = available_methods(); "
        "heavy = [k for k in sys.modules if k.startswith(('diffusers', 'peft', 'setdiff_bench.models', "
        "'setdiff_bench.enhancers.setdiff', 'setdiff_bench.enhancers.reproject'))]; "
        "print(sorted(m)); print(heavy)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert out[0] == str(sorted(["identity", "reproject", "precomputed", "setdiff", "difix"]))
    assert out[1] == "[]"


def test_builtin_specs() -> None:
    methods = available_methods()
    assert list(methods)[:5] == ["identity", "reproject", "precomputed", "setdiff", "difix"]
    assert not methods["identity"].needs_weights and methods["setdiff"].needs_weights
    assert all(spec.source == "builtin" for spec in BUILTIN_METHODS.values())


def test_identity_returns_the_render() -> None:
    from setdiff_bench.types import Packet, ViewSet

    camera = camera_at(0.0)
    image = torch.from_numpy(plane_view(camera, 2.0)[0].transpose(2, 0, 1).copy())[None]
    views = ViewSet(("a",), image, torch.zeros_like(image), torch.ones_like(image[:, :1]), (camera,))
    packet = Packet("p", "d", "p", "g", "test", "s", views, views)
    enhancer = create_enhancer("identity")
    assert isinstance(enhancer, IdentityEnhancer) and isinstance(enhancer, Enhancer)
    out = enhancer.enhance(packet)
    assert torch.equal(out, image) and out.data_ptr() != image.data_ptr()


def test_unknown_method_and_options_are_one_line_errors() -> None:
    with pytest.raises(UsageError, match="unknown method 'nope'; available: difix, identity"):
        create_enhancer("nope")
    with pytest.raises(
        UsageError, match=r"^method: method .identity. does not take source \(it takes: no options\)$"
    ):
        create_enhancer("identity", source="x")
    assert isinstance(create_enhancer("identity", optional={"device": "cuda"}), IdentityEnhancer)


def test_register_builtin_adds_a_spec(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(
        BUILTIN_METHODS, "copy", MethodSpec("copy", "setdiff_bench.enhancers.identity:create", "x")
    )
    register_builtin(MethodSpec("copy", "setdiff_bench.enhancers.identity:create", "a copy of identity"))
    assert available_methods()["copy"].description == "a copy of identity"
    assert isinstance(create_enhancer("copy"), IdentityEnhancer)


def test_plugin_through_an_entry_point(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.syspath_prepend(str(install_plugin(tmp_path / "site")))
    spec = available_methods()["darken"]
    assert spec.source == "darken = setdiff_test_plugin:SPEC" and spec.factory == "setdiff_test_plugin:create"
    enhancer = create_enhancer("darken", factor=0.25)
    assert enhancer.options == {"factor": 0.25}
    assert main(["list", "methods"]) == 0
    line = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("darken"))
    assert "test plugin: multiplies the render by a factor" in line and "[plugin: darken = " in line
    assert main(["list", "methods", "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert {
        "name": "darken",
        "description": "test plugin: multiplies the render by a factor",
        "needs_weights": False,
        "needs_gpu": False,
        "source": "darken = setdiff_test_plugin:SPEC",
    } in rows


def test_plugin_cannot_shadow_a_builtin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(
        str(install_plugin(tmp_path / "site", name="identity", module="shadow_plugin"))
    )
    with pytest.warns(RegistryWarning, match="already defined by 'builtin'"):
        methods = available_methods()
    assert methods["identity"].source == "builtin"


def test_broken_plugin_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(
        str(
            install_plugin(
                tmp_path / "site", name="broken", module="broken_plugin", target="broken_plugin:NOPE"
            )
        )
    )
    with pytest.raises(
        UsageError, match=r"entry point broken = broken_plugin:NOPE .*cannot load plugin method"
    ):
        available_methods()


def test_plugin_entry_point_must_give_a_method_spec(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(
        str(
            install_plugin(
                tmp_path / "site", name="notspec", module="notspec_plugin", target="notspec_plugin:create"
            )
        )
    )
    with pytest.raises(UsageError, match="plugin method is a Darken, expected a MethodSpec"):
        available_methods()


def test_list_methods_cli(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["list", "methods"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["METHOD", "WEIGHTS", "GPU", "DESCRIPTION"]
    rows = {line.split()[0]: line.split()[1:3] for line in lines[1:]}
    assert rows["identity"] == ["no", "no"] and rows["setdiff"] == ["yes", "no"]
