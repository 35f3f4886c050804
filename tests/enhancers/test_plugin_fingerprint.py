"""A plugin method's spec reaches the registry whole: its ``fingerprint`` too, so that ``run`` records the SHA-256
of its weights and refuses a resume with other weights, exactly as for the built-in checkpoint methods."""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import json
import sys
import textwrap
from pathlib import Path

import pytest

from setdiff_bench.enhancers.base import MethodSpec, available_methods
from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.io.run_layout import METRICS_FILE, RUN_FILE
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store

MODULE = "setdiff_fingerprint_plugin"
PLUGIN = '''
"""A test plugin with weights: scales every target by the number stored in its weights file."""
import hashlib
from pathlib import Path

from setdiff_bench.enhancers.base import MethodSpec

SPEC = MethodSpec(
    name="scaled",
    factory="{module}:create",
    description="test plugin: multiplies the render by the factor in --weights",
    needs_weights=True,
    options={{"weights": ""}},
    fingerprint="{module}:fingerprint",
)


class Scaled:
    name = "scaled"

    def __init__(self, weights):
        self.factor = float(Path(weights).read_text())
        self.options = {{"weights": str(weights)}}

    def enhance(self, packet):
        return packet.targets.images * self.factor


def create(weights):
    return Scaled(weights)


def fingerprint(weights):
    return {{Path(weights).name: hashlib.sha256(Path(weights).read_bytes()).hexdigest()}}
'''


@pytest.fixture
def plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> MethodSpec:
    """The plugin installed as ``pip install`` would (module + dist-info with its entry point); its own spec."""
    site = tmp_path / "site"
    site.mkdir()
    (site / f"{MODULE}.py").write_text(textwrap.dedent(PLUGIN.format(module=MODULE)))
    info = site / f"{MODULE}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {MODULE}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[setdiff_bench.enhancers]\nscaled = {MODULE}:SPEC\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.delitem(sys.modules, MODULE, raising=False)
    return importlib.import_module(MODULE).SPEC


def test_the_registry_keeps_every_field_of_a_plugin_spec(plugin: MethodSpec) -> None:
    registered = available_methods()["scaled"]
    assert registered.source == f"scaled = {MODULE}:SPEC"
    for field in dataclasses.fields(MethodSpec):
        if field.name != "source":
            assert getattr(registered, field.name) == getattr(plugin, field.name), field.name
    assert registered.fingerprint == f"{MODULE}:fingerprint"


def test_a_resumed_run_with_other_plugin_weights_is_refused(plugin: MethodSpec, tmp_path: Path) -> None:
    with torch_threads(1):
        store = build_store(tmp_path / "store", StoreSpec(groups=("lane+1",)))
    weights = tmp_path / "factor.txt"
    weights.write_text("0.5")
    settings = RunSettings("scaled", {"weights": str(weights)}, metrics=("psnr",), warp="off")
    out = tmp_path / "run"
    with torch_threads(1):
        run_method(store, out, settings, progress=False)
        assert json.loads((out / RUN_FILE).read_text())["model_files"] == {
            "factor.txt": hashlib.sha256(b"0.5").hexdigest()
        }
        # the same command with the same weights resumes ...
        assert run_method(store, out, settings, progress=False).merged
        # ... other weights behind the same option are refused, and the run is left as it was
        metrics_before = (out / METRICS_FILE).read_bytes()
        weights.write_text("0.25")
        with pytest.raises(UsageError, match=r"other model files \(their SHA-256 differ\)"):
            run_method(store, out, settings, progress=False)
    assert (out / METRICS_FILE).read_bytes() == metrics_before
