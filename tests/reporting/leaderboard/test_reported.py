"""Every number in protocols/reported/*.csv against the paper's tables, typed here a second time.

The values below were typed from the paper's LaTeX (main Tables 1–6, supplement Tables "architecture
ablation" and "consistency"), row by row in the paper's own layout, independently of the CSV files.
Both directions are checked: every typed number is in the CSV with the same printed digits, and the
CSV holds nothing else.
"""

from __future__ import annotations

import csv
from importlib import resources

import pytest

from setdiff_bench.reporting.leaderboard import load_reported

# table id -> (setting labels in column order, metrics per setting, rows "Method | v v v ...")
PAPER: dict[str, tuple[list[str], list[str], str]] = {
    "table1_euvs": (
        ["Setting 1", "Setting 2", "Setting 3"],
        ["psnr", "ssim", "lpips"],
        """
        reconstruction | 3DGS | 16.37 0.720 0.260 19.53 0.751 0.267 14.99 0.717 0.405
        reconstruction | 2DGS | 16.30 0.710 0.289 18.83 0.720 0.292 11.36 0.545 0.546
        reconstruction | GSPro | 16.39 0.719 0.245 19.39 0.747 0.225 14.82 0.699 0.388
        reconstruction | PGSR | 16.32 0.710 0.273 18.38 0.712 0.253 14.25 0.698 0.436
        reconstruction | 3DGM | 16.35 0.725 0.254 18.78 0.746 0.281 14.60 0.723 0.405
        reconstruction | Feature 3DGS | 16.01 0.724 0.257 19.59 0.786 0.228 14.33 0.639 0.382
        reconstruction | Zip-NeRF | 14.06 0.692 0.342 17.36 0.672 0.358 14.42 0.656 0.454
        reconstruction | Instant-NGP | 12.65 0.625 0.594 17.15 0.721 0.517 14.39 0.710 0.659
        enhancer | 3DGS | 16.37 0.720 0.260 19.53 0.751 0.267 14.99 0.717 0.405
        enhancer | 3DGS + VEGS | 15.88 0.705 0.306 23.33 0.795 0.281 14.25 0.647 0.442
        enhancer | 3DGS + DIFIX3D | 17.09 0.739 0.224 20.02 0.713 0.187 14.84 0.665 0.328
        enhancer | 3DGS + DIFIX3D++ | 17.94 0.782 0.218 21.68 0.772 0.209 15.91 0.743 0.335
        enhancer | 3DGS + SetDiff | 17.84 0.796 0.192 22.55 0.796 0.172 16.60 0.745 0.291
    """,
    ),
    "table2_paralane": (
        ["Single-lane transition", "Double-lane transition"],
        ["psnr", "ssim", "lpips"],
        """
        reconstruction | 3DGS | 17.05 0.524 0.446 16.26 0.505 0.472
        reconstruction | 2DGS | 16.79 0.523 0.469 16.01 0.510 0.494
        reconstruction | GSPro | 17.01 0.521 0.446 16.29 0.505 0.472
        reconstruction | Scaffold-GS | 17.59 0.538 0.450 17.09 0.525 0.470
        reconstruction | StreetGS | 17.50 0.510 0.456 16.16 0.496 0.480
        enhancer | 3DGS | 17.05 0.524 0.446 16.26 0.505 0.472
        enhancer | 3DGS + DIFIX3D | 17.62 0.470 0.234 16.87 0.447 0.271
        enhancer | 3DGS + DIFIX3D++ | 19.25 0.559 0.275 18.55 0.538 0.311
        enhancer | 3DGS + SetDiff | 20.20 0.586 0.208 19.47 0.564 0.233
    """,
    ),
    "table3_nuscenes": (
        ["All"],
        ["psnr", "ssim", "lpips"],
        """
        enhancer | OmniRe | 17.15 0.645 0.448
        enhancer | OmniRe + DIFIX3D | 17.12 0.612 0.371
        enhancer | OmniRe + DIFIX3D++ | 18.74 0.696 0.375
        enhancer | OmniRe + SetDiff | 21.58 0.716 0.303
    """,
    ),
    "table4_dl3dv": (
        ["3 views", "6 views", "9 views"],
        ["psnr", "ssim", "lpips"],
        """
        reconstruction | 3DGS | 10.97 0.248 0.567 13.34 0.332 0.498 14.99 0.403 0.446
        reconstruction | Mip-NeRF | 10.92 0.191 0.618 11.56 0.199 0.608 12.42 0.218 0.600
        reconstruction | RegNeRF | 11.46 0.214 0.600 12.69 0.236 0.579 12.33 0.219 0.598
        reconstruction | FreeNeRF | 10.91 0.211 0.595 12.13 0.230 0.576 12.85 0.241 0.573
        reconstruction | DNGaussian | 11.10 0.273 0.579 12.67 0.329 0.547 13.44 0.365 0.539
        enhancer | 3DGS | 10.97 0.248 0.567 13.34 0.332 0.498 14.99 0.403 0.446
        enhancer | 3DGS + DIFIX3D | 14.90 0.460 0.338 16.90 0.527 0.266 17.86 0.560 0.235
        enhancer | 3DGS + 3DGS-Enhancer | 14.33 0.424 0.464 16.94 0.565 0.356 18.50 0.630 0.305
        enhancer | 3DGS + DIFIX3D++ | 15.93 0.528 0.361 17.95 0.589 0.291 18.93 0.619 0.262
        enhancer | 3DGS + SetDiff | 16.87 0.533 0.335 18.74 0.587 0.264 19.60 0.614 0.232
    """,
    ),
    "table5_geometry_ablation": (
        ["Geometric grounding"],
        ["psnr", "ssim", "lpips"],
        """
        ablation | None | 17.59 0.164 0.278
        ablation | Coordinate maps | 18.39 0.557 0.282
        ablation | Camera poses | 18.43 0.560 0.288
        ablation | Both | 18.74 0.587 0.265
    """,
    ),
    "supp_architecture_ablation": (
        ["Architecture"],
        ["psnr", "ssim", "lpips"],
        """
        ablation | w/o LoRA | 18.604 0.584 0.287
        ablation | cross-attn | 18.673 0.587 0.268
        ablation | Ours | 18.74 0.587 0.265
    """,
    ),
    "supp_consistency": (
        ["All"],
        ["warp", "psnr", "ssim", "lpips"],
        """
        enhancer | OmniRe | 111.0 17.15 0.645 0.448
        enhancer | OmniRe + DiFix++ | 110.2 18.74 0.696 0.375
        enhancer | OmniRe + SetDiff | 108.9 21.58 0.716 0.303
    """,
    ),
}

# Table 6 is transposed in the paper: one row per metric, one column per |I^r| + |I^t|.
TABLE6_SIZES = ["1 + 1", "2 + 1", "3 + 1", "3 + 2", "3 + 4", "3 + 6"]
TABLE6 = {
    "psnr": "17.80 18.57 18.67 18.69 18.72 18.79",
    "ssim": "0.552 0.578 0.581 0.582 0.583 0.590",
    "lpips": "0.280 0.258 0.255 0.255 0.255 0.256",
}

# The numbers the paper sets in bold, per table: (method, setting, metric).
BOLD = {
    "table1_euvs": {
        ("3DGS + VEGS", "Setting 2", "psnr"),
        ("3DGS + DIFIX3D++", "Setting 1", "psnr"),
        ("3DGS + SetDiff", "Setting 1", "ssim"),
        ("3DGS + SetDiff", "Setting 1", "lpips"),
        ("3DGS + SetDiff", "Setting 2", "ssim"),
        ("3DGS + SetDiff", "Setting 2", "lpips"),
        ("3DGS + SetDiff", "Setting 3", "psnr"),
        ("3DGS + SetDiff", "Setting 3", "ssim"),
        ("3DGS + SetDiff", "Setting 3", "lpips"),
    },
    "table4_dl3dv": {
        ("3DGS + SetDiff", "3 views", "psnr"),
        ("3DGS + SetDiff", "3 views", "ssim"),
        ("3DGS + SetDiff", "3 views", "lpips"),
        ("3DGS + SetDiff", "6 views", "psnr"),
        ("3DGS + DIFIX3D++", "6 views", "ssim"),
        ("3DGS + SetDiff", "6 views", "lpips"),
        ("3DGS + SetDiff", "9 views", "psnr"),
        ("3DGS + 3DGS-Enhancer", "9 views", "ssim"),
        ("3DGS + SetDiff", "9 views", "lpips"),
    },
    "table6_setsize_ablation": {
        ("SetDiff", "3 + 6", "psnr"),
        ("SetDiff", "3 + 6", "ssim"),
        ("SetDiff", "3 + 1", "lpips"),
    },
}


def expected_values() -> dict[tuple[str, str, str, str, str], str]:
    """(table, section, method, setting, metric) -> printed value, from the typed tables above."""
    expected: dict[tuple[str, str, str, str, str], str] = {}
    for table, (settings, metrics, text) in PAPER.items():
        for line in filter(None, (raw.strip() for raw in text.splitlines())):
            section, method, numbers = (part.strip() for part in line.split("|"))
            values = numbers.split()
            assert len(values) == len(settings) * len(metrics), line
            for i, setting in enumerate(settings):
                for j, metric in enumerate(metrics):
                    expected[(table, section, method, setting, metric)] = values[i * len(metrics) + j]
    for metric, numbers in TABLE6.items():
        for size, value in zip(TABLE6_SIZES, numbers.split()):
            expected[("table6_setsize_ablation", "ablation", "SetDiff", size, metric)] = value
    return expected


def csv_rows() -> list[dict[str, str]]:
    folder = resources.files("setdiff_bench.protocols") / "reported"
    rows: list[dict[str, str]] = []
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".csv"):
            with entry.open(newline="") as handle:
                rows.extend(csv.DictReader(handle))
    return rows


def test_every_paper_number_is_transcribed_exactly() -> None:
    expected = expected_values()
    found = {
        (r["table"], r["section"], r["method"], r["setting"], r["metric"]): r["value"] for r in csv_rows()
    }
    assert len(csv_rows()) == len(found), "duplicate rows in protocols/reported"
    missing = sorted(set(expected) - set(found))
    extra = sorted(set(found) - set(expected))
    assert not missing, f"not transcribed: {missing[:5]}"
    assert not extra, f"not in the paper: {extra[:5]}"
    wrong = {key: (found[key], value) for key, value in expected.items() if found[key] != value}
    assert not wrong, f"(csv, paper) differ: {wrong}"
    assert len(expected) == 117 + 54 + 12 + 90 + 12 + 18 + 9 + 12


def test_bold_markers_match_the_paper() -> None:
    for table, cells in BOLD.items():
        bold = {
            (r["method"], r["setting"], r["metric"])
            for r in csv_rows()
            if r["table"] == table and r["bold"] == "1"
        }
        assert bold == cells, table


@pytest.mark.parametrize(
    "dataset, table",
    [
        ("euvs", "table1_euvs"),
        ("paralane", "table2_paralane"),
        ("nuscenes", "table3_nuscenes"),
        ("dl3dv", "table4_dl3dv"),
    ],
)
def test_load_reported_parses_values_and_precision(dataset: str, table: str) -> None:
    frame = load_reported(dataset, tables=[table])
    expected = {key: value for key, value in expected_values().items() if key[0] == table}
    assert len(frame) == len(expected)
    for row in frame.itertuples():
        printed = expected[(table, row.section, row.method, row.setting, row.metric)]
        assert row.value == float(printed)
        assert row.decimals == len(printed.split(".")[1])
        assert row.source == "reported"
