"""Issue 38/45 papercuts: ``fit --dataset D --root R`` fits the root's only scene without ``--scene``, and the
loader-option flag has one documented spelling (``-o KEY=VALUE`` / ``--loader-option KEY=VALUE``) accepted by
every verb of these files that reads a dataset (``list scenes``, ``fit``; the older ``--option`` still works).

Inputs are a generated tiny synthetic scene (one root holding it alone, one holding two copies); the expected
lines are written out here.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.synthetic.generate import generate_scene
from setdiff_bench.synthetic.presets import get_preset

SCENE = "scene_0000_00"
FIT = ["--preset", "tiny", "--iterations", "2", "--device", "cpu", "--no-progress"]


@pytest.fixture(scope="module")
def roots(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """``(root of one scene, root of two scenes)``."""
    one = tmp_path_factory.mktemp("one_scene")
    with torch_threads(1):
        scene = generate_scene(one, get_preset("tiny"), 0, 0)
    assert scene.name == SCENE
    two = tmp_path_factory.mktemp("two_scenes")
    shutil.copytree(scene, two / SCENE)
    shutil.copytree(scene, two / "scene_0000_01")
    return one, two


def one_line(capsys: pytest.CaptureFixture[str]) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_fit_takes_the_only_scene_of_a_root(
    roots: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Without ``--scene`` the root's one scene is fitted: the same PLY, byte for byte, as naming it."""
    one, _ = roots
    implicit, named = tmp_path / "implicit.ply", tmp_path / "named.ply"
    assert main(["fit", "--dataset", "synthetic", "--root", str(one), "--out", str(implicit), *FIT]) == 0
    assert capsys.readouterr().out.strip().endswith(f"-> {implicit}")
    argv = ["fit", "--dataset", "synthetic", "--root", str(one), "--scene", SCENE, "--out", str(named), *FIT]
    assert main(argv) == 0
    assert implicit.read_bytes() == named.read_bytes()


def test_fit_on_a_root_of_several_scenes_asks_for_one(
    roots: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, two = roots
    out = tmp_path / "fit.ply"
    assert main(["fit", "--dataset", "synthetic", "--root", str(two), "--out", str(out), *FIT]) == 2
    assert one_line(capsys) == (
        f"setdiff-bench fit: error: --scene: {two} holds 2 synthetic scenes (scene_0000_00, scene_0000_01); "
        "pick one with --scene"
    )
    assert main(["fit", "--out", str(out), *FIT]) == 2
    assert one_line(capsys) == (
        "setdiff-bench fit: error: --scene: needed: a scene folder, or --dataset D --root R (whose only scene "
        "is then fitted)"
    )
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flag", ["-o", "--loader-option", "--option"])
def test_every_spelling_reaches_the_loader(
    flag: str, roots: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    one, _ = roots
    listing = ["list", "scenes", "--dataset", "synthetic", "--root", str(one), "--names-only"]
    assert main([*listing, flag, "masks=optional"]) == 0
    assert capsys.readouterr().out.split() == [SCENE]
    refused = "synthetic loader has no option 'bogus'; options: masks, distortion"
    assert main([*listing, flag, "bogus=1"]) == 2
    assert one_line(capsys) == f"setdiff-bench list: error: {refused}"
    out = tmp_path / "fit.ply"
    assert (
        main(["fit", "--dataset", "synthetic", "--root", str(one), "--out", str(out), flag, "bogus=1", *FIT])
        == 2
    )
    assert one_line(capsys) == f"setdiff-bench fit: error: {refused}"
    packets = tmp_path / "packets"
    prepare = ["prepare", "synthetic", "--root", str(one), "--fits", str(one), "--out", str(packets)]
    assert main([*prepare, flag, "bogus=1", "--no-progress"]) == 2
    assert one_line(capsys).endswith(refused)
    assert not packets.exists()
    assert main([*listing, flag, "no_value"]) == 2
    assert one_line(capsys) == (
        "setdiff-bench list: error: -o/--loader-option: option 'no_value' must look like KEY=VALUE"
    )
    assert not out.exists()


@pytest.mark.parametrize("verb", [["list", "scenes"], ["fit"], ["prepare"]])
def test_help_documents_one_spelling(verb: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main([*verb, "--help"])
    text = capsys.readouterr().out
    assert "-o KEY=VALUE, --loader-option KEY=VALUE" in text
    assert "--option" not in text
