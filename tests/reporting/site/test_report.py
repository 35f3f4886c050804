"""``setdiff-bench report``: the site's files, its refusals, and the site in a real headless Chromium (loads from
disk without console errors, the before/after slider moves, the targets sort, a video plays)."""

from __future__ import annotations

import importlib.util
import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.reporting.site import target_sequences, write_video
from setdiff_bench.reporting.targets import error_map
from tests.reporting.site.browser import Browser, find_browser
from tests.reporting.site.conftest import SPEC


def test_site_holds_every_page_picture_and_video(site: Path, runs: Path) -> None:
    pages = sorted((site / "targets").glob("*.html"))
    assert len(pages) == len(SPEC.scenes) * len(SPEC.groups) * SPEC.targets
    for folder in (site / "images").iterdir():
        names = {p.name for p in folder.iterdir()}
        assert names == {
            "render.jpg",
            "gt.jpg",
            "render.err.jpg",
            "reproject.jpg",
            "reproject.err.jpg",
            "thumb.jpg",
        }
    videos = sorted((site / "videos").glob("*.webm"))
    sequences = len(SPEC.scenes) * len(SPEC.groups)  # one camera sequence per scene and group
    assert len(videos) == sequences  # one compared method
    assert sorted(p.stem for p in (site / "videos").glob("*.jpg")) == [v.stem for v in videos]  # posters
    capture = cv2.VideoCapture(str(videos[0]))
    frames = 0
    while capture.read()[0]:
        frames += 1
    assert frames == SPEC.targets
    index = (site / "index.html").read_text(encoding="utf-8")
    assert "reproject PSNR gain (dB)" in index and "identity" in index
    # self-contained: no network address and no absolute link anywhere
    for page in [site / "index.html", site / "videos.html", *pages]:
        text = page.read_text(encoding="utf-8")
        assert not re.search(r"(?:src|href)=\"(?:https?:|//|/)", text), page
        assert "<link" not in text and "http://" not in text and "https://" not in text
        for link in re.findall(r"(?:src|href)=\"([^\"#]+)", text):
            assert (page.parent / link).is_file(), (page, link)


def test_rows_start_with_the_largest_loss(site: Path, runs: Path) -> None:
    identity = pd.read_parquet(runs / "identity" / "metrics.parquet").set_index(["packet_id", "view"])
    method = pd.read_parquet(runs / "reproject" / "metrics.parquet").set_index(["packet_id", "view"])
    gains = (method["psnr"] - identity["psnr"]).sort_values()
    index = (site / "index.html").read_text(encoding="utf-8")
    body = index.split('<table class="sortable targets">', 1)[1]
    first_row = body.split("<tbody>", 1)[1].split("</tr>", 1)[0]
    shown = re.findall(r"data-v=\"([^\"]+)\"", first_row)
    # target and group (names), the baseline's PSNR, SSIM, LPIPS, then reproject's PSNR gain
    assert float(shown[2 + len(["psnr", "ssim", "lpips"])]) == pytest.approx(gains.iloc[0])


def test_error_map_is_black_where_equal_and_bright_at_full_scale() -> None:
    truth = np.zeros((4, 4, 3), np.uint8)
    image = truth.copy()
    image[0, 0] = 64  # 0.25 of full scale: the brightest colour
    heat = error_map(image, truth)
    assert heat.shape == (4, 4, 3) and heat.dtype == np.uint8
    assert heat[1, 1].sum() < 10 and heat[0, 0].sum() > 500


def test_sequences_follow_camera_and_time(runs: Path) -> None:
    rows = pd.read_parquet(runs / "reproject" / "metrics.parquet")
    sequences = target_sequences(rows)
    assert [(s.scene, s.group) for s in sequences] == [(a, g) for a in SPEC.scenes for g in SPEC.groups]
    for sequence in sequences:
        stamps = [
            rows.set_index(["packet_id", "view"]).loc[(k.packet_id, k.view), "timestamp_us"]
            for k in sequence.targets
        ]
        assert stamps == sorted(stamps) and len(stamps) == SPEC.targets


def test_video_only_writes_the_videos_alone(store: Path, runs: Path, tmp_path: Path) -> None:
    out = tmp_path / "videos"
    argv = ["report", "--runs", str(runs), "--packets", str(store), "--out", str(out), "--video-only"]
    assert main(argv) == 0
    assert sorted(p.name for p in out.iterdir()) == ["videos"]
    assert len(list((out / "videos").glob("*.webm"))) == len(SPEC.scenes) * len(SPEC.groups)


def test_refusals_are_one_line_and_write_nothing(
    store: Path, runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    other = tmp_path / "other_store"
    from tests.evaluation.run.store_fixtures import StoreSpec, build_store

    build_store(other, StoreSpec(scenes=("scene_z",)))
    elsewhere = tmp_path / "copied_runs"  # runs whose manifests name a store that is not on this machine
    shutil.copytree(runs, elsewhere)
    for manifest in elsewhere.glob("*/manifest.json"):
        record = json.loads(manifest.read_text(encoding="utf-8"))
        record["packets"]["root"] = str(tmp_path / "gone")
        manifest.write_text(json.dumps(record), encoding="utf-8")
    out = tmp_path / "site"
    cases = [
        (["--runs", str(runs), "--packets", str(other)], "was made on another packet store"),
        (["--runs", str(tmp_path / "missing")], "runs folder not found"),
        (["--runs", str(runs), "--baseline", "difix"], "no run of the baseline method 'difix'"),
        (["--runs", str(runs), "--fps", "0"], "positive frame rate"),
        (["--runs", str(elsewhere), "--video-only"], "videos need the packet store"),
    ]
    for argv, message in cases:
        capsys.readouterr()
        assert main(["report", *argv, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1 and err.startswith("setdiff-bench report: error:"), err
        assert not out.exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no staging folder left


def test_write_video_refuses_no_frames(tmp_path: Path) -> None:
    from setdiff_bench.reporting.site import VideoError

    with pytest.raises(VideoError, match="no frames"):
        write_video(tmp_path / "v.webm", [])
    assert not list(tmp_path.iterdir())


def test_site_in_headless_chromium(site: Path, tmp_path: Path) -> None:
    """The site loads from disk in a real browser without console errors; the slider moves; the targets
    table sorts on a click; a video plays (its currentTime advances)."""
    executable = find_browser()
    if executable is None:
        pytest.skip("no Chromium installed (apt-get install -y chromium) for the report's browser test")
    if importlib.util.find_spec("websocket") is None:
        pytest.skip("websocket-client (the test extra) is not installed for the report's browser test")
    target_page = sorted((site / "targets").glob("*.html"))[0]
    with Browser(executable, tmp_path / "profile") as browser:
        browser.open(site / "index.html")
        assert browser.evaluate("document.querySelectorAll('table.board').length") == 1
        assert browser.evaluate(  # the plots (thumbnails load lazily; their files are checked above)
            "Array.from(document.images).filter(i => i.loading !== 'lazy')"
            ".every(i => i.complete && i.naturalWidth > 0)"
        ), "an image of the index did not load"
        # the page opens sorted by the first gain column (marked ascending); a click reverses it, another
        # click sorts it ascending again: the first row holds the maximum, then the minimum
        column = browser.evaluate(
            "Array.from(document.querySelectorAll('table.targets th')).findIndex(t => /gain/.test(t.textContent))"
        )
        values = browser.evaluate(
            f"""(() => {{ const th = document.querySelectorAll('table.targets th')[{column}];
                const first = () => parseFloat(document.querySelector('table.targets tbody tr').cells[{column}].dataset.v);
                const opened = [first(), th.getAttribute('aria-sort')];
                th.click(); const down = [first(), th.getAttribute('aria-sort')];
                th.click(); const up = [first(), th.getAttribute('aria-sort')];
                const all = Array.from(document.querySelectorAll('table.targets tbody tr')).map(r => parseFloat(r.cells[{column}].dataset.v));
                return [opened, down, up, Math.min(...all), Math.max(...all)]; }})()"""
        )
        opened, down, up, low, high = values
        assert opened == [low, "ascending"] and down == [high, "descending"] and up == [low, "ascending"]
        # the target and group columns sort by name, in natural order, both ways
        for column, key in ((0, "target"), (1, "group")):
            names = browser.evaluate(
                f"""(() => {{ const th = document.querySelectorAll('table.targets th')[{column}];
                    const col = () => Array.from(document.querySelectorAll('table.targets tbody tr')).map(r => r.cells[{column}].dataset.v);
                    th.click(); const up = col(); th.click(); return [up, col()]; }})()"""
            )
            expected = sorted(names[0], key=natural_key)
            assert names[0] == expected and names[1] == expected[::-1], key

        browser.open(target_page)
        assert browser.evaluate("Array.from(document.images).every(i => i.complete && i.naturalWidth > 0)")
        before = browser.evaluate("document.querySelector('.cmp .before').style.clipPath")
        after = browser.evaluate(
            """(() => { const s = document.querySelector('.cmp input'); s.value = 20;
                s.dispatchEvent(new Event('input', {bubbles: true}));
                return document.querySelector('.cmp .before').style.clipPath; })()"""
        )
        assert "50%" in before and "80%" in after, (before, after)

        browser.open(site / "videos.html")
        # before it plays, a player shows its poster (the first frame), not a black box
        browser.evaluate(
            """(async () => { const p = new Image(); p.src = document.querySelector('video').poster;
                await p.decode(); await new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r))); })()"""
        )
        shown = cv2.imdecode(np.frombuffer(browser.screenshot("video"), np.uint8), cv2.IMREAD_COLOR)
        assert shown is not None and shown.mean() > 40, "the video shows black before it plays"
        played = browser.evaluate(
            """(async () => { const v = document.querySelector('video'); await v.play();
                const start = performance.now();
                while (v.currentTime === 0 && performance.now() - start < 10000) {
                  await new Promise(r => setTimeout(r, 50)); }
                return [v.currentTime, v.videoWidth, v.error === null]; })()"""
        )
        assert played[0] > 0 and played[1] > 0 and played[2], played
        assert browser.errors == [], browser.errors


def test_a_run_evaluated_under_a_profile_is_reported_once(runs: Path, tmp_path: Path) -> None:
    """``evaluate`` writes ``<run>/profiles/<profile>/metrics.parquet`` (scores without images); ``report``
    takes the run, not the profile's table as another run (it crashed reading an ``image`` column there)."""
    import shutil

    import pandas as pd

    from setdiff_bench.reporting.site import run_folders

    copied = tmp_path / "runs"
    shutil.copytree(runs, copied)
    before = run_folders([copied])
    first = next(iter(before.values()))
    profile = first / "profiles" / "paper"
    profile.mkdir(parents=True)
    scores = pd.read_parquet(first / "metrics.parquet").drop(columns=["image", "image_sha256"])
    scores.assign(profile="paper").to_parquet(profile / "metrics.parquet")
    assert run_folders([copied]) == before
