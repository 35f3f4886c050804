"""Issue 57: the plugin template in ``examples/plugin_enhancer`` installs as its README says (pip, no network),
registers its method through the ``setdiff_bench.enhancers`` entry point, and scores; its unsharp mask is
checked against scipy's Gaussian filter."""

from __future__ import annotations

import importlib
import shutil
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.ndimage import gaussian_filter

import setdiff_bench as sb
from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.base import ENTRY_POINT_GROUP
from setdiff_bench.io.run_layout import METRICS_FILE
from tests.evaluation.run.store_fixtures import run_argv

TEMPLATE = Path(__file__).resolve().parents[3] / "examples" / "plugin_enhancer"


@pytest.fixture(scope="module")
def installed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The template installed by pip into a folder of its own (no dependencies, no build isolation, no index:
    nothing is downloaded), as ``pip install`` would put it into site-packages."""
    target = tmp_path_factory.mktemp("site")
    build = tmp_path_factory.mktemp("build")  # a copy: pip's build leaves files beside the sources
    # nothing from the network: no dependencies, the build backend already installed, no package index
    offline = ["--no-deps", "--no-build-isolation", "--no-index", "--disable-pip-version-check", "--quiet"]
    source = _copy(TEMPLATE, build)
    subprocess.run(
        [sys.executable, "-m", "pip", "install", *offline, f"--target={target}", str(source)],
        check=True,
        capture_output=True,
    )
    return target


def _copy(source: Path, folder: Path) -> Path:
    return Path(
        shutil.copytree(source, folder / source.name, ignore=shutil.ignore_patterns("*.egg-info", "build"))
    )


@pytest.fixture
def registered(installed: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.syspath_prepend(str(installed))
    importlib.invalidate_caches()
    yield installed
    for name in [m for m in sys.modules if m.startswith("setdiff_unsharp")]:
        del sys.modules[name]


def test_the_entry_point_the_template_declares_is_the_one_installed(registered: Path) -> None:
    declared = tomllib.loads((TEMPLATE / "pyproject.toml").read_text())["project"]["entry-points"]
    assert declared == {ENTRY_POINT_GROUP: {"unsharp": "setdiff_unsharp.spec:SPEC"}}
    spec = sb.available_methods()["unsharp"]
    assert (
        spec.source == "unsharp = setdiff_unsharp.spec:SPEC"
        and spec.factory == "setdiff_unsharp.enhancer:create"
    )
    assert Path(importlib.import_module("setdiff_unsharp").__file__).is_relative_to(registered)


def test_the_template_method_scores_against_an_independent_unsharp_mask(
    registered: Path, store: Path
) -> None:
    enhancer = sb.create_enhancer("unsharp", amount=0.8, sigma=1.5)
    assert repr(enhancer) == "UnsharpMaskEnhancer('unsharp', amount=0.8, sigma=1.5)"
    packets = sb.PacketStore(store)
    packet_id = packets.packet_ids("test")[0]
    renders = packets.load_packet(packet_id).targets.images.numpy().astype(np.float64)
    # scipy: the same Gaussian (radius int(3 sigma + 0.5)) with mirrored borders, per image and channel
    blurred = gaussian_filter(renders, sigma=(0, 0, 1.5, 1.5), mode="mirror", truncate=3.0)
    expected = np.clip(renders + 0.8 * (renders - blurred), 0.0, 1.0)
    np.testing.assert_allclose(enhancer.enhance(packets.load_packet(packet_id)).numpy(), expected, atol=1e-5)
    score = sb.score_packet(enhancer, packets, packet_id)
    assert (
        np.rint(expected * 255).astype(np.uint8).tolist()
        == np.rint(score.enhanced.numpy() * 255).astype(np.uint8).tolist()
    )


def test_the_readme_commands_run_the_template(registered: Path, store: Path, tmp_path: Path) -> None:
    out = tmp_path / "unsharp"
    assert main(run_argv("unsharp", store, out, "-o", "amount=0.5")) == 0
    rows = pd.read_parquet(out / METRICS_FILE)
    assert set(rows["method"]) == {"unsharp"} and len(rows) == 12 and rows["psnr"].notna().all()
