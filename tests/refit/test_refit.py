"""The refit end to end on a small street scene: output, ground truth kept out, resume, bad inputs."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch

from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.base import BUILTIN_METHODS, MethodSpec
from setdiff_bench.errors import CheckpointError
from setdiff_bench.gaussians.ply import read_ply, write_ply
from setdiff_bench.io.refit_layout import refit_paths
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.refit import RefitSettings, RefitTask, refit_scene
from setdiff_bench.refit.loop import RefitLoop
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.types import Packet

SCENE = "street_00"
#: 6 steps, updates before steps 1 and 4 (t = 0.5, then the targets), step 4 on a pseudo-view (r = 0.7)
SETTINGS = RefitSettings.preset("progressive", steps=6, update_every=3, checkpoint_every=2)


def task(root: Path, out: Path, method: str = "reproject", **fields: object) -> RefitTask:
    chosen: dict[str, object] = {"fits": root, **fields}
    return RefitTask("synthetic", root, SCENE, out, method, group="lane+2", **chosen)  # type: ignore[arg-type]


@pytest.fixture(scope="module")
def finished(street_root: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An uninterrupted refit with :data:`SETTINGS` (its output folder)."""
    out = tmp_path_factory.mktemp("refit") / "out"
    with torch_threads(1):  # as every test (tests/conftest.py): the same bytes need the same thread count
        refit_scene(task(street_root, out), SETTINGS, progress=False)
    return out


def test_refit_writes_a_ply_prepare_can_render_and_a_manifest(
    finished: Path, street_root: Path, tmp_path: Path
) -> None:
    manifest = json.loads(refit_paths(finished, SCENE, "lane0")[1].read_text())
    ply = finished / SCENE / "lane0.ply"
    assert manifest["ply"]["path"] == f"{SCENE}/lane0.ply"
    assert (manifest["group"], manifest["fit_key"], manifest["updates"]) == ("lane+2", "lane0", 2)
    assert manifest["pseudo_views"] == manifest["targets"] == 5  # the lane+2 front camera's 5 timesteps
    assert manifest["enhancer"]["method"] == "reproject" and manifest["schedule"]["steps"] == 6
    assert manifest["time"]["steps_run"] == 6 and manifest["peak_memory_mb"] > 0
    assert not refit_paths(finished, SCENE, "lane0")[2].exists()
    refit, fit = read_ply(ply), read_ply(street_root / SCENE / "fits" / "lane0.ply")
    # Adam moves a parameter by at most about its rate per step: 6 steps x 1.6e-6 x extent (~25 m) < 1e-3
    assert float((refit.means - fit.means).abs().max()) < 1e-3
    assert not torch.equal(refit.sh, fit.sh)
    # scoring X 3D: prepare renders the refit scene from OUT as it renders any fit folder
    from setdiff_bench.packets.prepare import prepare

    prepare("synthetic", street_root, tmp_path / "store", fits=finished, groups=["lane+2"], progress=False)
    store = PacketStore(tmp_path / "store")
    assert store.index["fit_key"].eq("lane0").all() and len(store) == 1


def test_rerun_of_a_finished_refit_changes_nothing(finished: Path, street_root: Path) -> None:
    before = refit_paths(finished, SCENE, "lane0")[1].read_bytes()
    result = refit_scene(task(street_root, finished), SETTINGS, progress=False)
    assert result.already_done and result.manifest_path.read_bytes() == before


def test_ground_truth_of_the_targets_never_reaches_the_refit(
    finished: Path, street_root: Path, tmp_path: Path
) -> None:
    poisoned = tmp_path / "poisoned"
    shutil.copytree(street_root, poisoned)
    train = set((poisoned / SCENE / "train_set.txt").read_text().split())
    rng = np.random.default_rng(0)
    for image in (poisoned / SCENE / "images").iterdir():
        if image.name not in train:  # every recorded frame but the fit frames, the lane+2 targets included
            noise = rng.integers(0, 256, cv2.imread(str(image)).shape, dtype=np.uint8)
            assert cv2.imwrite(str(image), noise)
    out = tmp_path / "out"
    refit_scene(task(poisoned, out), SETTINGS, progress=False)
    assert (out / SCENE / "lane0.ply").read_bytes() == (finished / SCENE / "lane0.ply").read_bytes()


def test_interrupted_refit_resumes_to_the_same_bytes(
    finished: Path, street_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    save = RefitLoop.save

    def save_then_stop(loop: RefitLoop, folder: Path) -> None:
        save(loop, folder)
        # stop after the second update: the pseudo-views and their order must come from the checkpoint
        if loop.step_count == 4:
            raise KeyboardInterrupt

    out = tmp_path / "out"
    monkeypatch.setattr(RefitLoop, "save", save_then_stop)
    with pytest.raises(KeyboardInterrupt):
        refit_scene(task(street_root, out), SETTINGS, progress=False)
    assert not any(path.exists() for path in refit_paths(out, SCENE, "lane0")[:2])
    monkeypatch.setattr(RefitLoop, "save", save)
    result = refit_scene(task(street_root, out), SETTINGS, progress=False)
    assert result.resumed_at == 4
    assert (out / SCENE / "lane0.ply").read_bytes() == (finished / SCENE / "lane0.ply").read_bytes()


class WrongShape:
    """An enhancer that drops a row of pixels."""

    name = "wrong_shape"

    def enhance(self, packet: Packet) -> torch.Tensor:
        return packet.targets.images[:, :, 1:]


def wrong_shape() -> WrongShape:
    return WrongShape()


def refit_cli(root: Path, out: Path, *extra: str) -> list[str]:
    return [
        "refit",
        "synthetic",
        "--root",
        str(root),
        "--scene",
        SCENE,
        "--out",
        str(out),
        "--steps",
        "4",
        "--no-progress",
        *extra,
    ]


@pytest.mark.parametrize("case", ["wrong shape", "other scene's fit", "poses outside the scene"])
def test_bad_inputs_get_one_line_exit_2_and_nothing_written(
    case: str,
    street_root: Path,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    monkeypatch.setitem(
        BUILTIN_METHODS, "wrong_shape", MethodSpec("wrong_shape", "tests.refit.test_refit:wrong_shape", "x")
    )
    out = tmp_path / "out"
    fits, method, targets = street_root, "identity", ["--group", "lane+2"]
    if case == "wrong shape":
        method = "wrong_shape"
    elif case == "other scene's fit":
        fit = read_ply(street_root / SCENE / "fits" / "lane0.ply")
        fit.means = fit.means[:, [1, 0, 2]]  # the street along the other axis: another scene's layout
        fits = tmp_path / "fits"
        write_ply(fits / SCENE / "lane0.ply", fit)
    else:
        targets = ["--trajectory", "shift:1000"]
    code = main(refit_cli(street_root, out, "--fits", str(fits), "--method", method, *targets))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("setdiff-bench refit: error:")
    expected = {
        "wrong shape": "wrong_shape",
        "other scene's fit": "another scene",
        "poses outside the scene": "scene bounds",
    }
    assert expected[case] in err[0]
    assert not any(path.exists() for path in refit_paths(out, SCENE, "lane0")[:2])


@pytest.mark.slow  # two CLI processes (torch start-up); test_interrupted_refit_resumes_to_the_same_bytes covers resume fast
def test_sigkill_mid_refit_then_rerun_gives_the_same_bytes(street_root: Path, tmp_path: Path) -> None:
    import os
    import signal
    import subprocess
    import sys
    import time

    settings = RefitSettings.preset("progressive", steps=40, update_every=10, checkpoint_every=2)
    reference = tmp_path / "reference"
    refit_scene(task(street_root, reference), settings, progress=False)
    out = tmp_path / "out"
    command = [sys.executable, "-m", "setdiff_bench", *refit_cli(street_root, out)]
    command[command.index("--steps") + 1] = "40"
    command += ["--update-every", "10", "--checkpoint-every", "2", "--fits", str(street_root)]
    command += ["--group", "lane+2", "--method", "reproject"]
    env = {**os.environ, "SETDIFF_THREADS": "1"}
    process = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    latest = refit_paths(out, SCENE, "lane0")[2] / "LATEST"
    deadline = time.monotonic() + 120
    while (
        not (latest.is_file() and latest.read_text().strip() >= "step-000012") and time.monotonic() < deadline
    ):
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    assert not refit_paths(out, SCENE, "lane0")[1].exists(), "the refit finished before it could be killed"
    rerun = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    assert "resumed at step" in rerun.stdout
    assert (out / SCENE / "lane0.ply").read_bytes() == (reference / SCENE / "lane0.ply").read_bytes()


def fit_checkpoint(root: Path, folder: Path, model_path: Path) -> None:
    """A fit checkpoint (``fit --checkpoint``) whose parameters are the PLY at ``model_path``: the state a fit of
    the lane+2 group's fit frames ends with."""
    from setdiff_bench.gaussians.fit import FitConfig, Trainer, load_fit_views, save_checkpoint
    from setdiff_bench.loaders import load_scenes
    from setdiff_bench.protocols import load_protocol

    scene = load_scenes("synthetic", root, [SCENE])[0]
    frames = load_protocol("synthetic").group("lane+2").select(scene).fit
    views = load_fit_views(scene, [f.name for f in frames])
    trainer = Trainer(views, read_ply(model_path), FitConfig(), torch.device("cpu"))
    save_checkpoint(trainer, folder, [v.name for v in views])


def test_fit_checkpoint_must_hold_the_ply(street_root: Path, tmp_path: Path) -> None:
    fit = street_root / SCENE / "fits" / "lane0.ply"
    settings = RefitSettings.preset("one-shot", steps=1)
    fit_checkpoint(street_root, tmp_path / "ckpt", fit)
    result = refit_scene(
        task(street_root, tmp_path / "a", fit_checkpoint=tmp_path / "ckpt"), settings, progress=False
    )
    assert result.manifest["identity"]["fit_checkpoint"] is not None
    other = read_ply(fit)
    other.opacity_logits = other.opacity_logits - 1.0
    write_ply(tmp_path / "other.ply", other)
    fit_checkpoint(street_root, tmp_path / "other_ckpt", tmp_path / "other.ply")
    with pytest.raises(CheckpointError, match="does not hold the PLY"):
        refit_scene(
            task(street_root, tmp_path / "b", fit_checkpoint=tmp_path / "other_ckpt"),
            settings,
            progress=False,
        )
    assert not refit_paths(tmp_path / "b", SCENE, "lane0")[1].exists()


def test_refit_fits_the_scene_first_without_fits(street_root: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    settings = RefitSettings.preset("one-shot", steps=1, min_fit_correlation=-1.0)  # a 2-iteration fit
    result = refit_scene(task(street_root, out, fits=None, fit_iterations=2), settings, progress=False)
    assert Path(result.manifest["fit"]["path"]) == (out / "base" / "fits" / SCENE / "lane0.ply").resolve()
    assert (out / SCENE / "lane0.ply").is_file()


def test_snapshots_are_the_plys_of_shorter_refits(finished: Path, street_root: Path, tmp_path: Path) -> None:
    """A snapshot after k steps is what a refit of k steps ends with (the schedule's prefix does not depend on its
    length), also when the refit was interrupted after it and resumed; the last one is the refit itself."""
    from setdiff_bench.io.refit_layout import snapshot_folder

    out = tmp_path / "snap"
    with_snapshots = dataclasses.replace(SETTINGS, snapshot_every=3)
    save = RefitLoop.save
    stopped = []

    def stop_once(loop: RefitLoop, folder: Path) -> None:
        save(loop, folder)
        if loop.step_count == 4 and not stopped:
            stopped.append(True)
            raise KeyboardInterrupt

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(RefitLoop, "save", stop_once)
        with pytest.raises(KeyboardInterrupt):
            refit_scene(task(street_root, out), with_snapshots, progress=False)
    result = refit_scene(task(street_root, out), with_snapshots, progress=False)
    assert result.resumed_at == 4
    short = tmp_path / "short"
    refit_scene(task(street_root, short), dataclasses.replace(SETTINGS, steps=3), progress=False)
    at_3 = snapshot_folder(out, 3) / SCENE / "lane0.ply"
    assert at_3.read_bytes() == (short / SCENE / "lane0.ply").read_bytes()
    at_6 = snapshot_folder(out, 6) / SCENE / "lane0.ply"
    assert at_6.read_bytes() == (finished / SCENE / "lane0.ply").read_bytes() != at_3.read_bytes()
    assert [(s["step"], s["path"]) for s in result.manifest["snapshots"]] == [
        (3, f"snapshots/step-000003/{SCENE}/lane0.ply"),
        (6, f"snapshots/step-000006/{SCENE}/lane0.ply"),
    ]
    # a snapshot folder is a fits folder
    from setdiff_bench.packets.prepare import prepare

    prepare(
        "synthetic",
        street_root,
        tmp_path / "store",
        fits=snapshot_folder(out, 3),
        groups=["lane+2"],
        progress=False,
    )
    assert len(PacketStore(tmp_path / "store")) == 1


def test_the_refit_takes_the_split_of_the_packets_it_is_scored_on(street_root: Path, tmp_path: Path) -> None:
    """A scene's split chooses its packets' shape and reference count; ``--test-scene`` declares it as
    ``prepare --test-scene`` does, and the manifest records which split the refit used."""
    from setdiff_bench.errors import UsageError
    from setdiff_bench.loaders import list_scenes
    from setdiff_bench.packets.prepare import declared_split
    from setdiff_bench.protocols import load_protocol

    settings = dataclasses.replace(SETTINGS, steps=1)
    protocol_split = load_protocol("synthetic").split.assign(list_scenes("synthetic", street_root))[SCENE]
    plain = refit_scene(task(street_root, tmp_path / "plain"), settings, progress=False)
    assert plain.manifest["identity"]["split"] == protocol_split
    other = "test" if protocol_split == "train" else "train"
    declared = (SCENE,) if other == "test" else ()
    assert declared_split({SCENE: protocol_split}, declared)[SCENE] == other
    result = refit_scene(
        task(street_root, tmp_path / "declared", test_scenes=declared), settings, progress=False
    )
    assert result.manifest["identity"]["split"] == other
    with pytest.raises(UsageError, match="no scene 'elsewhere'"):
        refit_scene(task(street_root, tmp_path / "x", test_scenes=("elsewhere",)), settings, progress=False)
