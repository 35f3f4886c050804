"""`setdiff-bench run` on real packet stores: outputs, independent metric checks, precomputed, resume, shards."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import torch
from safetensors.numpy import load_file
from skimage.metrics import structural_similarity

from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.identity import IdentityEnhancer
from setdiff_bench.errors import ImageError, UsageError
from setdiff_bench.evaluation.packet_scoring import EnhancerOutputError
from setdiff_bench.evaluation.run import RunSettings, comparable_metrics, run_method
from setdiff_bench.io import run_layout as paths
from setdiff_bench.io.run_layout import IMAGES_DIR, MANIFEST_FILE, METRICS_FILE, RUN_FILE, SEQUENCES_FILE
from setdiff_bench.metrics.warp import warp_error, warp_reference
from setdiff_bench.metrics.weights import resolve_lpips_weights
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.shards import Shard
from setdiff_bench.packets.store import PacketStore
from tests.enhancers.plugin_fixtures import install_plugin
from tests.evaluation.run.store_fixtures import StoreSpec, build_store, files_of, run_argv
from tests.metrics.lpips_numpy import lpips_numpy

ONE_THREAD = {**os.environ, "OMP_NUM_THREADS": "1"}  # subprocesses: tiny images, busy machine
#: A run's metrics.parquet columns: the key columns the evaluation declares, then the scores and the image.
COLUMNS = [
    *paths.KEY_COLUMNS,
    "psnr",
    "ssim",
    "lpips",
    "ms_per_frame",
    "peak_memory_mb",
    "image",
    "image_sha256",
]


def read_rgb_cv2(path: Path) -> np.ndarray:
    """An 8-bit PNG as float64 RGB in [0, 1], read with OpenCV (not the project's reader)."""
    return cv2.imread(str(path), cv2.IMREAD_COLOR)[:, :, ::-1].astype(np.float64) / 255.0


def store_rows(store: Path) -> pd.DataFrame:
    index = pd.read_parquet(store / INDEX_FILE)
    return index[index["role"] == "target"].set_index(["packet_id", "view"])


def same_results(a: Path, b: Path, *, method_b: str | None = None) -> None:
    """Images byte-identical and metrics equal except timing (and the method name when renamed)."""
    assert files_of(a) == files_of(b)
    left, right = comparable_metrics(a / METRICS_FILE), comparable_metrics(b / METRICS_FILE)
    if method_b:
        right = right.assign(method=left["method"])
    pd.testing.assert_frame_equal(left, right)


def fragments(out: Path) -> list[Path]:
    """Complete fragment files (a write in flight is a hidden temporary file)."""
    return [p for p in out.glob("fragments/*.parquet") if not p.name.startswith(".")]


class FailingIdentity(IdentityEnhancer):
    """Identity that dies on its ``fail_at``-th packet (a crash in the middle of a run)."""

    def __init__(self, fail_at: int) -> None:
        super().__init__()
        self.calls, self.fail_at = 0, fail_at

    def enhance(self, packet):  # type: ignore[no-untyped-def]
        self.calls += 1
        if self.calls == self.fail_at:
            raise RuntimeError("simulated crash")
        return super().enhance(packet)


# ---------------------------------------------------------------------- outputs and metrics
def test_identity_run_writes_images_metrics_and_manifest(store: Path, identity_run: Path) -> None:
    metrics = pd.read_parquet(identity_run / METRICS_FILE)
    assert list(metrics.columns) == COLUMNS
    assert len(metrics) == 12 and set(metrics["method"]) == {"identity"}
    assert list(metrics["packet_id"]) == sorted(metrics["packet_id"])
    targets = store_rows(store)
    for row in metrics.itertuples():
        target = targets.loc[(row.packet_id, row.view)]
        assert row.frame == target["frame"] and row.group == target["group"] and row.scene == target["scene"]
        written = identity_run / row.image
        assert row.image == f"images/synthetic/{row.group}/{row.scene}/{Path(row.frame).with_suffix('')}.png"
        assert row.image_sha256 == hashlib.sha256(written.read_bytes()).hexdigest()
        output = read_rgb_cv2(written)
        np.testing.assert_array_equal(output, read_rgb_cv2(store / target["image"]))
        gt = read_rgb_cv2(store / target["gt"])
        mask = cv2.imread(str(store / target["mask"]), cv2.IMREAD_GRAYSCALE) > 127
        mse = ((output - gt) ** 2)[mask].mean()
        assert row.psnr == pytest.approx(10 * np.log10(1 / mse), rel=1e-6)
        if mask.all():
            expected = structural_similarity(
                output,
                gt,
                gaussian_weights=True,
                sigma=1.5,
                use_sample_covariance=False,
                data_range=1.0,
                channel_axis=-1,
            )
            assert row.ssim == pytest.approx(expected, abs=1e-5)
    assert (~metrics["psnr"].between(20, 30)).sum() == 0


def test_lpips_column_equals_an_independent_numpy_lpips(store: Path, identity_run: Path) -> None:
    row = pd.read_parquet(identity_run / METRICS_FILE).iloc[1]  # the partly masked target
    target = store_rows(store).loc[(row["packet_id"], row["view"])]
    mask = (cv2.imread(str(store / target["mask"]), cv2.IMREAD_GRAYSCALE) > 127)[:, :, None]
    assert not mask.all()
    pred, gt = read_rgb_cv2(identity_run / row["image"]) * mask, read_rgb_cv2(store / target["gt"]) * mask
    weights = load_file(str(resolve_lpips_weights("alex")))
    assert row["lpips"] == pytest.approx(lpips_numpy(pred, gt, weights, "alex", True), abs=2e-5)


def test_manifest_records_method_versions_device_and_index_hash(store: Path, identity_run: Path) -> None:
    manifest = json.loads((identity_run / MANIFEST_FILE).read_text())
    assert manifest["method"]["name"] == "identity"
    assert manifest["method"]["factory"] == "setdiff_bench.enhancers.identity:create"
    assert (
        manifest["packets"]["index_sha256"] == hashlib.sha256((store / INDEX_FILE).read_bytes()).hexdigest()
    )
    assert manifest["packets"]["targets"] == 12 and manifest["packets"]["packets"] == 4
    assert manifest["versions"]["torch"] == torch.__version__.split("+")[0] or manifest["versions"]["torch"]
    assert set(manifest["git"]) == {"revision", "dirty"}
    assert manifest["device"]["type"] == "cpu"
    assert manifest["timing"]["frames"] == 12
    assert (
        set(manifest["metrics"]["image"]) == {"psnr", "ssim", "lpips"} and manifest["metrics"]["warp"] is None
    )


# ---------------------------------------------------------------------- precomputed
def test_precomputed_on_a_copy_of_identity_outputs_gives_identical_metrics(
    store: Path, identity_run: Path, tmp_path: Path
) -> None:
    copy = tmp_path / "external"
    shutil.copytree(identity_run / IMAGES_DIR, copy)
    run_method(store, tmp_path / "pre", RunSettings("precomputed", {"source": str(copy)}), progress=False)
    same_results(identity_run, tmp_path / "pre", method_b="identity")
    # a run folder itself also works (its images/ is used)
    run_method(
        store, tmp_path / "pre2", RunSettings("precomputed", {"source": str(identity_run)}), progress=False
    )
    same_results(identity_run, tmp_path / "pre2", method_b="identity")


def test_precomputed_scene_level_layout(store: Path, identity_run: Path, tmp_path: Path) -> None:
    flat = tmp_path / "flat"
    for png in (identity_run / IMAGES_DIR).glob(
        "*/*/*/*/*.png"
    ):  # images/<protocol>/<group>/<scene>/front/x.png
        scene, sub, name = png.parts[-3], png.parts[-2], png.name
        (flat / scene / sub).mkdir(parents=True, exist_ok=True)
        shutil.copy(png, flat / scene / sub / name)
    run_method(store, tmp_path / "pre", RunSettings("precomputed", {"source": str(flat)}), progress=False)
    same_results(identity_run, tmp_path / "pre", method_b="identity")


def test_precomputed_missing_frames_are_listed(
    store: Path, identity_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "external"
    shutil.copytree(identity_run / IMAGES_DIR, copy)
    (copy / "synthetic/lane+2/scene_b/front/000004.png").unlink()
    (copy / "synthetic/lane+1/scene_a/front/000001.png").unlink()
    with pytest.raises(
        UsageError,
        match=r"2 of 12 target frames have no precomputed image: "
        r"scene_a/front/000001.jpg \(lane\+1\), scene_b/front/000004.jpg \(lane\+2\)",
    ):
        run_method(store, tmp_path / "pre", RunSettings("precomputed", {"source": str(copy)}), progress=False)
    assert not list((tmp_path / "pre").glob("fragments/*"))
    code = main(run_argv("precomputed", store, tmp_path / "pre_cli", "--from", str(copy)))
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "2 of 12 target frames have no precomputed image" in err[0]


def test_precomputed_wrong_size_names_the_file(store: Path, identity_run: Path, tmp_path: Path) -> None:
    copy = tmp_path / "external"
    shutil.copytree(identity_run / IMAGES_DIR, copy)
    bad = copy / "synthetic/lane+1/scene_a/front/000000.png"
    cv2.imwrite(str(bad), np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(
        ImageError, match=r"000000\.png: precomputed image for scene_a/front/000000\.jpg: image is 10x10"
    ):
        run_method(store, tmp_path / "pre", RunSettings("precomputed", {"source": str(copy)}), progress=False)


def test_precomputed_needs_from(store: Path, tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"^source: method 'precomputed' needs a folder of enhanced images$"):
        run_method(store, tmp_path / "pre", RunSettings("precomputed"), progress=False)


# ---------------------------------------------------------------------- resume, shards, idempotence
def test_crashed_run_resumes_to_identical_outputs(store: Path, identity_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "crashed"
    with pytest.raises(RuntimeError, match="simulated crash"):
        run_method(store, out, RunSettings("identity"), enhancer=FailingIdentity(fail_at=3), progress=False)
    assert len(fragments(out)) == 2 and not (out / METRICS_FILE).exists()
    result = run_method(store, out, RunSettings("identity"), progress=False)
    assert (result.enhanced, result.skipped, result.merged) == (2, 2, True)
    same_results(identity_run, out)


def test_sigkilled_run_resumes_to_identical_outputs(store: Path, identity_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "killed"
    script = (
        "import sys, time\n"
        "from setdiff_bench.enhancers.identity import IdentityEnhancer\n"
        "from setdiff_bench.evaluation.run import RunSettings, run_method\n"
        "class Slow(IdentityEnhancer):\n"
        "    def enhance(self, packet):\n"
        "        time.sleep(0.4)\n"
        "        return super().enhance(packet)\n"
        "run_method(sys.argv[1], sys.argv[2], RunSettings('identity'), enhancer=Slow(), progress=False)\n"
    )
    process = subprocess.Popen(
        [sys.executable, "-c", script, str(store), str(out)], cwd=Path(__file__).parents[3], env=ONE_THREAD
    )
    deadline = time.monotonic() + 60
    while not fragments(out) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    done = len(fragments(out))
    assert 1 <= done < 4, "the kill must land mid-run"
    result = run_method(store, out, RunSettings("identity"), progress=False)
    assert result.enhanced == 4 - done and result.merged
    same_results(identity_run, out)
    assert not list(out.rglob(".*.tmp*"))


def test_two_shards_merge_to_the_single_run(store: Path, identity_run: Path, tmp_path: Path) -> None:
    out = tmp_path / "sharded"
    first = run_method(store, out, RunSettings("identity"), shard=Shard(0, 2), progress=False)
    assert (first.enhanced, first.remaining, first.merged) == (2, 2, False)
    assert not (out / METRICS_FILE).exists()
    second = run_method(store, out, RunSettings("identity"), shard=Shard(1, 2), progress=False)
    assert (second.enhanced, second.remaining, second.merged) == (2, 0, True)
    same_results(identity_run, out)


def test_concurrent_shard_processes_into_one_new_folder(
    store: Path, identity_run: Path, tmp_path: Path
) -> None:
    out = tmp_path / "parallel"
    processes = [
        subprocess.Popen(
            [
                sys.executable,
                "-m",
                "setdiff_bench",
                *run_argv("identity", store, out, "--shard", f"{i}/2", "--device", "cpu"),
            ],
            cwd=Path(__file__).parents[3],
            env=ONE_THREAD,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for i in range(2)
    ]
    results = [process.communicate(timeout=120) for process in processes]
    assert [process.returncode for process in processes] == [0, 0], results
    same_results(identity_run, out)


def test_second_run_does_nothing(store: Path, identity_run: Path) -> None:
    before = {
        p: (p.stat().st_mtime_ns, p.read_bytes())
        for p in (identity_run / METRICS_FILE, identity_run / MANIFEST_FILE)
    }
    result = run_method(store, identity_run, RunSettings("identity"), progress=False)
    assert (result.enhanced, result.skipped, result.merged) == (0, 4, True)
    assert {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in before} == before


def test_a_folder_with_other_settings_is_refused(store: Path, identity_run: Path, tmp_path: Path) -> None:
    with pytest.raises(UsageError, match=r"other settings \(method differ\)"):
        run_method(store, identity_run, RunSettings("reproject"), progress=False)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x.txt").write_text("x")
    with pytest.raises(UsageError, match=r"not empty and holds no run\.json"):
        run_method(store, tmp_path / "full", RunSettings("identity"), progress=False)


@pytest.mark.parametrize(
    "bad, message",
    [
        (lambda t: t[:, :2], r"shape \(3, 2, 32, 48\)"),
        (lambda t: t * float("nan"), "NaN"),
        (lambda t: (t * 255).to(torch.uint8), "dtype torch.uint8"),
    ],
)
def test_bad_enhancer_output_is_refused(store: Path, tmp_path: Path, bad, message: str) -> None:  # type: ignore[no-untyped-def]
    class Bad(IdentityEnhancer):
        def enhance(self, packet):  # type: ignore[no-untyped-def]
            return bad(super().enhance(packet))

    with pytest.raises(EnhancerOutputError, match=message):
        run_method(store, tmp_path / "bad", RunSettings("identity"), enhancer=Bad(), progress=False)
    assert not list((tmp_path / "bad").glob("fragments/*"))


# ---------------------------------------------------------------------- CLI, plugins, warp
def test_cli_run_and_one_line_errors(
    store: Path, identity_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "cli"
    assert main(run_argv("identity", store, out, "--device", "cpu")) == 0
    assert "enhanced 4 packets" in capsys.readouterr().out
    same_results(identity_run, out)
    for argv, fragment in (
        (["--packets", str(tmp_path / "none")], "no index.parquet here"),
        (["--packets", str(store), "--shard", "2/2"], "shard must be i/n with 0 <= i < n"),
        (["--packets", str(store), "--split", "train"], "no packets of split 'train'"),
        (["--packets", str(store), "--checkpoint", "x"], "does not take --checkpoint"),
    ):
        code = main(["run", "--method", "identity", "--out", str(tmp_path / "err"), "--no-progress", *argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and fragment in err[0], err


def test_plugin_method_runs(store: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.syspath_prepend(str(install_plugin(tmp_path / "site")))
    assert main(run_argv("darken", store, tmp_path / "darken", "-o", "factor=0.5")) == 0
    metrics = pd.read_parquet(tmp_path / "darken" / METRICS_FILE)
    assert set(metrics["method"]) == {"darken"} and len(metrics) == 12
    targets = store_rows(store)
    for row in metrics.head(3).itertuples():
        render = cv2.imread(str(store / targets.loc[(row.packet_id, row.view)]["image"]))
        written = cv2.imread(str(tmp_path / "darken" / row.image))
        assert np.abs(written.astype(int) - np.rint(render * 0.5).astype(int)).max() <= 1
    assert json.loads((tmp_path / "darken" / MANIFEST_FILE).read_text())["method"]["enhancer"]["options"] == {
        "factor": 0.5
    }


def test_warp_error_per_camera_sequence_across_groups(tmp_path: Path) -> None:
    spec = StoreSpec(
        dataset="nuscenes",
        protocol="nuscenes",
        groups=("10-11s", "11-12s"),
        scenes=("scene-0001",),
        sensors=("CAM_FRONT", "CAM_BACK"),
        targets=4,
        timestamps=True,
    )
    store = build_store(tmp_path / "store", spec)
    out, cache = tmp_path / "run", tmp_path / "flows"
    run_method(store, out, RunSettings("identity", flow_method="dis", warp_cache=str(cache)), progress=False)
    sequences = pd.read_parquet(out / SEQUENCES_FILE)
    cached = {p: p.stat().st_mtime_ns for p in cache.glob("*.safetensors")}
    assert len(cached) == 2  # one ground-truth flow per camera sequence
    # another method on the same store reuses the flows; a copy of identity's images scores the same
    run_method(
        store,
        tmp_path / "pre",
        RunSettings("precomputed", {"source": str(out)}, flow_method="dis", warp_cache=str(cache)),
        progress=False,
    )
    assert {p: p.stat().st_mtime_ns for p in cache.glob("*.safetensors")} == cached
    again = pd.read_parquet(tmp_path / "pre" / SEQUENCES_FILE)
    assert again["warp"].tolist() == sequences["warp"].tolist()
    assert list(sequences["sensor"]) == ["CAM_BACK", "CAM_FRONT"] and list(sequences["frames"]) == [4, 4]
    assert list(sequences["first_frame"]) == ["CAM_BACK/000001.jpg", "CAM_FRONT/000000.jpg"]
    assert list(sequences["last_frame"]) == ["CAM_BACK/000007.jpg", "CAM_FRONT/000006.jpg"]
    metrics = pd.read_parquet(out / METRICS_FILE)
    packets = PacketStore(store)
    for sequence in sequences.itertuples():
        rows = metrics[metrics["sensor"] == sequence.sensor].sort_values("timestamp_us")
        frames = torch.stack(
            [torch.from_numpy(read_rgb_cv2(out / p).transpose(2, 0, 1)).float() for p in rows["image"]]
        )
        gts, masks = zip(*(packets.load_ground_truth(r.packet_id, [r.view]) for r in rows.itertuples()))
        reference = warp_reference(torch.cat(gts), method="dis")
        expected = float(warp_error(frames, reference, torch.cat(masks)))
        assert sequence.warp == pytest.approx(expected, rel=1e-6)
    assert json.loads((out / MANIFEST_FILE).read_text())["metrics"]["warp"]["sequences"] == 2


def test_run_verb_takes_a_shipped_model_by_name(store: Path, tmp_path: Path) -> None:
    """``--checkpoint tiny_difix`` is a name, not a path under the working folder; run.json keeps the name."""
    import json

    from setdiff_bench.cli.main import main

    out = tmp_path / "difix"
    assert main(run_argv("difix", store, out, "--checkpoint", "tiny_difix", "--metrics", "psnr")) == 0
    assert json.loads((out / RUN_FILE).read_text())["options"] == {"checkpoint": "tiny_difix"}
    assert len(pd.read_parquet(out / METRICS_FILE)) > 0
