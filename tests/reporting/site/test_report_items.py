"""The report as a new user meets it (issue 57): posters for the videos, units on the numbers, plot captions
that say what a plot shows, the per-scene breakdown with its paired intervals, a marked initial sort, the
paper's rows where the leaderboard has them, and pictures small enough for a large benchmark."""

from __future__ import annotations

import html
import json
import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest
import scipy.stats

from setdiff_bench.reporting.grids import BAND, GAP
from setdiff_bench.reporting.site import SiteSettings, TargetRecord, build_site, write_target_images
from setdiff_bench.reporting.targets import TargetKey
from tests.reporting.site.conftest import SPEC

REPO = Path(__file__).resolve().parents[3]


def _index(site: Path) -> str:
    return (site / "index.html").read_text(encoding="utf-8")


def _first_frame(video: Path) -> np.ndarray:
    capture = cv2.VideoCapture(str(video))
    ok, frame = capture.read()
    capture.release()
    assert ok, video
    return frame


def test_every_video_has_a_poster_showing_its_first_frame(site: Path) -> None:
    pages = [site / "videos.html", *sorted((site / "targets").glob("*.html"))]
    players = 0
    for page in pages:
        for tag in re.findall(r"<video [^>]*>", page.read_text(encoding="utf-8")):
            players += 1
            poster = re.search(r'poster="([^"]+)"', tag)
            source = re.search(r'src="([^"]+)"', tag)
            assert poster and source, tag
            picture = cv2.imread(str(page.parent / html.unescape(poster.group(1))), cv2.IMREAD_COLOR)
            first = _first_frame(page.parent / html.unescape(source.group(1)))
            assert picture is not None and picture.shape == first.shape
            assert picture.mean() > 40  # not black: the render, the method and the ground truth side by side
            # the first frame, up to JPEG and VP9 losses (8-bit levels)
            assert np.abs(picture.astype(float) - first.astype(float)).mean() < 6
    assert players == len(SPEC.scenes) * len(SPEC.groups) * (1 + SPEC.targets)  # videos.html + each target


def test_numbers_carry_their_units(site: Path) -> None:
    index = _index(site)
    headers = re.findall(r"<th[^>]*>([^<]*)</th>", index)
    assert "PSNR (dB)↑" in headers  # the leaderboard
    assert "identity PSNR (dB)↑" in headers and "reproject PSNR gain (dB)" in headers  # the targets table
    assert "PSNR gain (dB)" in headers  # the per-scene breakdown
    assert "SSIM↑" in headers and "LPIPS↓" in headers  # unitless metrics get no unit
    page = sorted((site / "targets").glob("*.html"))[0].read_text(encoding="utf-8")
    assert "<th>PSNR (dB)↑</th>" in page and "<th>PSNR gain (dB)</th>" in page
    assert re.search(r"reproject — PSNR \d+\.\d\d dB</figcaption>", page)
    assert "largest error of the 2×2 pixels it covers" in page  # the half-size error maps say what they show


def test_plot_caption_says_what_the_plot_shows(site: Path) -> None:
    figures = re.findall(
        r'<figure><img src="(plots/[^"]+)" alt="([^"]*)"[^>]*><figcaption[^>]*>([^<]*)<', _index(site)
    )
    assert len(figures) == 1
    source, alt, caption = figures[0]
    assert Path(source).stem not in caption and alt == caption
    assert "lateral lane shift" in caption and "PSNR (dB)" in caption and "standard error" in caption


def test_targets_table_opens_sorted_and_says_so(site: Path, runs: Path) -> None:
    index = _index(site)
    table = index.split('<table class="sortable targets">', 1)[1].split("</thead>", 1)[0]
    marked = re.findall(r'<th class="([^"]*)" aria-sort="([^"]+)">([^<]*)</th>', table)
    assert marked == [("sortable asc", "ascending", "reproject PSNR gain (dB)")]
    assert "opens sorted by reproject&#x27;s PSNR gain, largest loss first" in index
    # target and group sort too, by name
    assert '<th class="l sortable" data-type="text">target</th>' in table
    assert '<th class="l sortable" data-type="text">group</th>' in table


def _scene_rows(index: str) -> list[tuple[str, str, list[dict[str, float]]]]:
    """``(group, scene, cells)`` of the per-scene table; each cell's gain, low and high."""
    table = index.split('<table class="scenes">', 1)[1].split("</table>", 1)[0]
    rows = []
    for row in table.split("<tbody>", 1)[1].split("</tr>")[:-1]:
        group, scene = re.findall(r'<td class="l">(?:<b>)?([^<]*)', row)
        cells = [
            {"gain": float(v), "low": float(lo), "high": float(hi)}
            for v, lo, hi in re.findall(r'data-v="([^"]+)" data-low="([^"]+)" data-high="([^"]+)"', row)
        ]
        rows.append((html.unescape(group), html.unescape(scene), cells))
    return rows


def test_per_scene_breakdown_with_paired_intervals(site: Path, runs: Path) -> None:
    keys = ["packet_id", "view"]
    identity = pd.read_parquet(runs / "identity" / "metrics.parquet").set_index(keys)
    method = pd.read_parquet(runs / "reproject" / "metrics.parquet").set_index(keys)
    gains = pd.DataFrame(
        {
            "scene": identity["scene"],
            "group": identity["group"],
            "psnr": method["psnr"] - identity["psnr"],
            "lpips": identity["lpips"] - method["lpips"],  # lower is better: the gain is the decrease
        }
    )
    rows = _scene_rows(_index(site))
    sections = [*SPEC.groups, "all groups"]
    assert [(g, s) for g, s, _ in rows] == [(g, s) for g in sections for s in (*SPEC.scenes, "all scenes")]
    for group, scene, cells in rows:
        psnr, lpips = cells[0], cells[2]  # PSNR, SSIM, LPIPS of reproject
        chosen = gains if group == "all groups" else gains[gains["group"] == group]
        if scene == "all scenes":
            means = chosen.groupby("scene")["psnr"].mean()
            assert psnr["gain"] == pytest.approx(chosen["psnr"].mean(), abs=1e-9)
            # two scenes with as many targets each: a resample is A+A, A+B or B+B, each end drawn ~1/4 of the
            # time, so the 2.5th and 97.5th percentiles are the two scene means
            assert (psnr["low"], psnr["high"]) == pytest.approx((means.min(), means.max()), abs=1e-9)
        else:
            values = chosen.loc[chosen["scene"] == scene, "psnr"].to_numpy()
            assert psnr["gain"] == pytest.approx(values.mean(), abs=1e-9)
            # within a scene the targets are resampled: scipy's percentile bootstrap from the same seed
            reference = scipy.stats.bootstrap(
                (values,),
                np.mean,
                n_resamples=10_000,
                method="percentile",
                random_state=np.random.default_rng(0),
            ).confidence_interval
            assert (psnr["low"], psnr["high"]) == pytest.approx((reference.low, reference.high), abs=1e-6)
            expected_lpips = chosen.loc[chosen["scene"] == scene, "lpips"].mean()
            assert lpips["gain"] == pytest.approx(expected_lpips, abs=1e-9)
            assert lpips["low"] <= lpips["gain"] <= lpips["high"]
    wins = int((gains.groupby("scene")["psnr"].mean() > 0).sum())
    assert f"better in {wins}/{len(SPEC.scenes)} scenes" in _index(site)


def test_paper_rows_where_the_leaderboard_has_them(site: Path, runs: Path, tmp_path: Path) -> None:
    """The synthetic benchmark has no paper table; the same runs read as DL3DV's 3 / 6 views get Table 4's
    rows, marked (paper), unless ``with_reported`` is off."""
    assert "(paper)" not in _index(site)
    relabelled = tmp_path / "runs"
    shutil.copytree(runs, relabelled)
    for table in relabelled.glob("*/metrics.parquet"):
        rows = pd.read_parquet(table)
        rows.assign(
            dataset="dl3dv", group=rows["group"].map(dict(zip(SPEC.groups, ("n3", "n6"))))
        ).to_parquet(table)
    for manifest in relabelled.glob("*/manifest.json"):  # no store: tables only, quicker
        record = json.loads(manifest.read_text(encoding="utf-8"))
        record["packets"]["root"] = str(tmp_path / "gone")
        manifest.write_text(json.dumps(record), encoding="utf-8")
    reported = pd.read_csv(REPO / "protocols" / "reported" / "dl3dv.csv", dtype=str)
    paper_rows = reported.loc[reported["table"] == "table4_dl3dv", "method"].unique()
    with_rows = build_site([relabelled], tmp_path / "with", settings=SiteSettings(videos=False))
    board = _index(with_rows.out).split('<table class="board">', 1)[1].split("</table>", 1)[0]
    labels = [html.unescape(label) for label in re.findall(r'<tr><td class="l">([^<]*)</td>', board)]
    assert labels == [f"{m} (paper)" for m in paper_rows] + ["identity", "reproject"]
    assert "3DGS + SetDiff (paper)" in labels
    row = board.split("3DGS + SetDiff (paper)", 1)[1].split("</tr>", 1)[0]
    assert re.findall(r"<td>(?:<b>)?([^<]*)", row)[:3] == [
        "16.87",
        "0.533",
        "0.335",
    ]  # paper Table 4, 3 views
    without = build_site(
        [relabelled], tmp_path / "without", settings=SiteSettings(videos=False, with_reported=False)
    )
    assert "(paper)" not in _index(without.out)


class _GridPictures:
    """One target's pictures cut from the published sparse demo's grid (256x144 renders of the shipped
    models), standing in for :class:`~setdiff_bench.reporting.targets.TargetImages`."""

    METHODS = ("reproject", "difix", "setdiff")

    def __init__(self, grid: np.ndarray, row: int) -> None:
        height, width, label, note = 144, 256, 150, 22
        top = BAND + row * (height + note + GAP)
        cells = [
            cv2.cvtColor(grid[top : top + height, label + c * (width + GAP) :][:, :width], cv2.COLOR_BGR2RGB)
            for c in range(5)
        ]
        self.cells = dict(zip(("render", *self.METHODS, "gt"), cells))

    def render(self, key: TargetKey) -> np.ndarray:
        return self.cells["render"]

    def ground_truth(self, key: TargetKey) -> np.ndarray:
        return self.cells["gt"]

    def output(self, label: str, key: TargetKey) -> np.ndarray:
        return self.cells[label]


#: The sparse benchmark's test targets, and the size its whole report must stay under.
SPARSE_TARGETS, SITE_BUDGET = 676, 100e6
#: The share of that budget the target pictures may take (the rest: pages, index, plots, videos).
PICTURE_SHARE = 0.6


def test_pictures_of_a_target_fit_the_sparse_report_budget(tmp_path: Path) -> None:
    """Real 256x144 pictures of the sparse demo (render, three methods, ground truth, four error maps and a
    thumbnail) take at most 60 % of 100 MB / 676 targets, and at least four times less than as PNG."""
    from setdiff_bench.reporting.site import PictureSettings

    record = TargetRecord(TargetKey("p", 0), "dl3dv", "s", "n3", "f", "t", {})
    grid = cv2.imread(str(REPO / "results" / "synthetic_sparse" / "dl3dv_grid.png"), cv2.IMREAD_COLOR)

    def written(row: int, lossless: bool) -> int:
        folder = tmp_path / f"{lossless}_{row}"
        pictures = _GridPictures(grid, row)
        write_target_images(pictures, record, pictures.METHODS, folder, PictureSettings(lossless))  # type: ignore[arg-type]
        return sum(p.stat().st_size for p in folder.iterdir())

    jpeg = [written(row, False) for row in range(6)]
    assert np.mean(jpeg) < PICTURE_SHARE * SITE_BUDGET / SPARSE_TARGETS, jpeg
    assert written(0, True) > 4 * jpeg[0]  # PNG (writing it is slow: one row)


def test_runs_are_labelled_by_their_display_name(site: Path, runs: Path, tmp_path: Path) -> None:
    """Two ``precomputed`` runs named apart (``run --name``: ``name`` in run.json, the rows' method column)
    keep their names in the report, not ``precomputed (folder)``."""
    from setdiff_bench.reporting.site import run_folders

    copied = tmp_path / "runs"
    shutil.copytree(runs, copied)
    for name in ("mine", "theirs"):
        folder = copied / f"precomputed_{name}"
        shutil.copytree(runs / "reproject", folder)
        record = json.loads((folder / "run.json").read_text(encoding="utf-8"))
        record.update(method="precomputed", name=name)
        (folder / "run.json").write_text(json.dumps(record), encoding="utf-8")
        rows = pd.read_parquet(folder / "metrics.parquet")
        rows.assign(method=name).to_parquet(folder / "metrics.parquet")
    assert sorted(run_folders([copied])) == ["identity", "mine", "reproject", "theirs"]


def test_half_size_error_maps_keep_a_single_wrong_pixel_bright() -> None:
    """Error maps of a JPEG site are stored at half size, each pixel the worst of its 2x2 block: one wrong
    pixel at the colour scale's top (0.25 of full scale = 64 levels) shows as inferno's brightest colour, not
    a quarter of it."""
    from setdiff_bench.reporting.site import pooled_error_map

    truth = np.zeros((4, 6, 3), np.uint8)
    image = truth.copy()
    image[3, 5] = 64
    heat = pooled_error_map(image, truth)
    brightest = cv2.applyColorMap(np.array([[255]], np.uint8), cv2.COLORMAP_INFERNO)[0, 0][::-1]  # to RGB
    black = cv2.applyColorMap(np.array([[0]], np.uint8), cv2.COLORMAP_INFERNO)[0, 0][::-1]
    assert heat.shape == (2, 3, 3)
    assert (heat[1, 2] == brightest).all()
    assert all((heat[r, c] == black).all() for r in range(2) for c in range(3) if (r, c) != (1, 2))


def test_video_panels_are_scaled_to_the_panel_width() -> None:
    from setdiff_bench.reporting.site import side_by_side

    wide = np.full((144, 256, 3), 120, np.uint8)
    narrow = np.full((108, 192, 3), 120, np.uint8)  # 256 x 144 at 192 pixels wide
    scaled = side_by_side(wide, wide, wide, "m", "1/2", panel_width=192)
    assert scaled.shape == side_by_side(narrow, narrow, narrow, "m", "1/2").shape
    assert side_by_side(wide, wide, wide, "m", "1/2", panel_width=None).shape[1] > scaled.shape[1] + 3 * 60


def test_report_takes_several_runs_options_like_leaderboard() -> None:
    import argparse

    from setdiff_bench.cli import report as report_verb

    parser = argparse.ArgumentParser()
    report_verb.add_arguments(parser)
    args = parser.parse_args(["--runs", "a", "--runs", "b", "c", "--out", "o"])
    assert [str(p) for p in args.runs] == ["a", "b", "c"]  # before: only the last --runs was kept
