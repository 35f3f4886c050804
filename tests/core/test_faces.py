"""Package faces: every name a face exports resolves, and a lazy face (``runtime.lazy.lazy_face``) imports none
of its private modules until a name is used."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
import types

import pytest

FACES = (
    "setdiff_bench.evaluation.run",
    "setdiff_bench.reporting.site",
    "setdiff_bench.reporting.ablation",
    "setdiff_bench.pipeline.demo",
    "setdiff_bench.synthetic.world",
    "setdiff_bench.synthetic.sparse",
    "setdiff_bench.gaussians.fit",
)


@pytest.mark.parametrize("face", FACES)
def test_every_exported_name_resolves_to_a_private_module_of_the_package(face: str) -> None:
    module = importlib.import_module(face)
    assert module.__all__ == sorted(module.__all__) or set(module.__all__) == set(dir(module)) & set(
        module.__all__
    )
    for name in module.__all__:
        value = getattr(module, name)
        if not isinstance(value, type | types.FunctionType):
            continue  # a constant or an instance (its __module__ is its class's)
        if value.__module__.startswith("setdiff_bench"):
            home = value.__module__
            assert home.startswith(face + "._"), f"{face}.{name} comes from {home}, not from the package"


def test_a_lazy_face_loads_only_what_is_used() -> None:
    code = (
        "import json, sys; import setdiff_bench.reporting.site as site; before = sorted(m for m in sys.modules "
        "if m.startswith('setdiff_bench.reporting.site.')); site.SiteSettings; after = sorted(m for m in "
        "sys.modules if m.startswith('setdiff_bench.reporting.site.')); print(json.dumps([before, after, "
        "site.__all__ == sorted(site._EXPORTS)]))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    before, after, all_matches = json.loads(result.stdout)
    assert before == [] and after == ["setdiff_bench.reporting.site._settings"] and all_matches
