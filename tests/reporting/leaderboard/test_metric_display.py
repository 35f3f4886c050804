"""Tables read each metric's display from its spec: ablation tables are written by the leaderboard's writers
(the same numbers print as the same cells), and a column without a spec is refused."""

from __future__ import annotations

import pandas as pd
import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.reporting import ablation
from setdiff_bench.reporting.leaderboard import build_leaderboard, render_latex, render_markdown

# Pooled means per geometry variant: PSNR of "Camera poses" and "Both" tie at two decimals, LPIPS at three.
GEOMETRY = {
    "none": {"psnr": 18.004, "ssim": 0.5504, "lpips": 0.3004, "targets": 12.0},
    "cmap": {"psnr": 18.5, "ssim": 0.56, "lpips": 0.29, "targets": 12.0},
    "pose": {"psnr": 19.004, "ssim": 0.57, "lpips": 0.2704, "targets": 12.0},
    "both": {"psnr": 18.996, "ssim": 0.58, "lpips": 0.27, "targets": 12.0},
}
LABELS = {"none": "None", "cmap": "Coordinate maps", "pose": "Camera poses", "both": "Both"}

# Written by hand: two decimals for PSNR, three for SSIM/LPIPS, bold on the best displayed value, ties share it.
MARKDOWN_ROWS = [
    "| None | 18.00 | 0.550 | 0.300 |",
    "| Coordinate maps | 18.50 | 0.560 | 0.290 |",
    "| Camera poses | **19.00** | 0.570 | **0.270** |",
    "| Both | **19.00** | **0.580** | **0.270** |",
]
LATEX_ROWS = [
    r"None & 18.00 & 0.550 & 0.300 \\",
    r"Coordinate maps & 18.50 & 0.560 & 0.290 \\",
    r"Camera poses & \textbf{19.00} & 0.570 & \textbf{0.270} \\",
    r"Both & \textbf{19.00} & \textbf{0.580} & \textbf{0.270} \\",
]


def leaderboard_of_the_same_numbers() -> pd.DataFrame:
    """One nuScenes target per method (the pooled block only), valued as the geometry variants."""
    return pd.DataFrame(
        [
            {
                "dataset": "nuscenes",
                "protocol": "nuscenes",
                "group": "10-11s",
                "split": "test",
                "scene": "s",
                "frame": "f0",
                "method": LABELS[key],
                "run": f"r/{key}",
                **{m: GEOMETRY[key][m] for m in ("psnr", "ssim", "lpips")},
            }
            for key in GEOMETRY
        ]
    )


def table_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("|")]


def test_ablation_and_leaderboard_cells_are_formatted_identically() -> None:
    frame = ablation.geometry_frame(GEOMETRY)
    markdown = ablation.geometry_markdown(frame, ablation.ordering_geometry(frame), "`cmd`", "Geometry")
    ours = table_lines(markdown)[:6]
    assert ours == [
        "| Geometric grounding | PSNR↑ | SSIM↑ | LPIPS↓ |",
        "|---|---:|---:|---:|",
        *MARKDOWN_ROWS,
    ]
    board = build_leaderboard("nuscenes", leaderboard_of_the_same_numbers(), methods=list(LABELS.values()))
    assert table_lines(render_markdown(board)) == [
        "| Method | PSNR↑ | SSIM↑ | LPIPS↓ |",
        "|---|---:|---:|---:|",
        *MARKDOWN_ROWS,
    ]
    latex = ablation.geometry_latex(frame, "Geometry")
    assert (
        r"\textbf{Geometric grounding} & \textbf{PSNR}$\uparrow$ & \textbf{SSIM}$\uparrow$ & "
        r"\textbf{LPIPS}$\downarrow$ \\" in latex.splitlines()
    )
    for row in LATEX_ROWS:
        assert row in latex.splitlines() and row in render_latex(board).splitlines()


def test_ablation_markdown_document() -> None:
    frame = ablation.geometry_frame(GEOMETRY)
    markdown = ablation.geometry_markdown(frame, ["PSNR: fine"], "`cmd`", "Geometry")
    assert markdown.startswith("**Geometry**\n\n| Geometric grounding |")
    assert (
        "\n\nPooled over 12 test targets per variant.\n\nOrdering against the paper:\n- PSNR: fine\n\n"
        in markdown
    )
    assert "**Paper, Table 5 (DL3DV; for orientation, not comparable numbers)**" in markdown
    assert "| Both (paper) | **18.74** | **0.587** | **0.265** |" in markdown
    assert markdown.endswith("\n\nProduced by:\n\n`cmd`")


def test_setsize_table_has_one_row_per_size_and_the_papers_bold() -> None:
    results = {
        (1, 1): {"psnr": 18.0, "ssim": 0.5, "lpips": 0.3, "targets": 8.0},
        (3, 6): {"psnr": 18.254, "ssim": 0.52, "lpips": 0.3001, "targets": 8.0},
    }
    frame = ablation.setsize_frame(results)
    assert list(frame["metric"]) == ["PSNR", "SSIM", "LPIPS"]  # the Parquet keeps the paper's shape
    markdown = ablation.setsize_markdown(frame, ablation.ordering_setsize(results), "`cmd`", "Sizes", 8)
    assert table_lines(markdown)[:4] == [
        "| References + targets | PSNR↑ | SSIM↑ | LPIPS↓ |",
        "|---|---:|---:|---:|",
        "| 1 + 1 | 18.00 | 0.500 | **0.300** |",
        "| 3 + 6 | **18.25** | **0.520** | **0.300** |",
    ]
    assert "Every set size scores the same 8 test targets." in markdown
    assert "| 3 + 1 (paper) | 18.67 | 0.581 | **0.255** |" in markdown  # the paper's own bold, not a tie rule
    assert "| 3 + 2 (paper) | 18.69 | 0.582 | 0.255 |" in markdown
    latex = ablation.setsize_latex(frame, "Sizes")
    assert r"3 + 6 & \textbf{18.25} & \textbf{0.520} & \textbf{0.300} \\" in latex.splitlines()


def test_a_metric_column_without_a_spec_is_refused() -> None:
    frame = leaderboard_of_the_same_numbers().assign(psnr_mine=1.0)
    with pytest.raises(UsageError, match="unknown metric"):  # no spec: no header, decimals or direction
        build_leaderboard("nuscenes", frame, metrics=["psnr_mine"])


def test_several_models_give_means_spread_and_paired_gains() -> None:
    seed0 = {
        (1, 1): {"psnr": 20.0, "ssim": 0.70, "lpips": 0.20, "targets": 8.0},
        (3, 1): {"psnr": 20.5, "ssim": 0.72, "lpips": 0.19, "targets": 8.0},
    }
    seed1 = {
        (1, 1): {"psnr": 21.0, "ssim": 0.74, "lpips": 0.22, "targets": 8.0},
        (3, 1): {"psnr": 20.9, "ssim": 0.75, "lpips": 0.21, "targets": 8.0},
    }
    means = ablation.mean_over_models([seed0, seed1])
    expected = {(1, 1): (20.5, 0.72, 0.21), (3, 1): (20.7, 0.735, 0.2)}  # by hand
    for size, values in expected.items():
        assert means[size]["targets"] == 8.0
        assert all(abs(means[size][m] - v) < 1e-12 for m, v in zip(("psnr", "ssim", "lpips"), values))
    ordering = ablation.ordering_setsize(means, [seed0, seed1])
    # PSNR gains by hand: +0.5 (seed 0), -0.1 (seed 1); LPIPS is lower-is-better, so +0.01 in both
    assert ordering[0].startswith(
        "PSNR: 3+1 vs 1+1 better (20.7000 vs 20.5000; gain per model +0.5000, -0.1000"
    )
    assert "better in 1 of 2" in ordering[0]
    assert "gain per model +0.0100, +0.0100, better in 2 of 2" in ordering[2]
    labels = {(1, 1): "1 + 1", (3, 1): "3 + 1"}
    notes = ablation.spread_notes([seed0, seed1], labels, ["seed 0", "seed 1"])
    assert notes[0] == "Each cell is the mean over 2 trained models (seed 0, seed 1)."
    # sd (n − 1) by hand: |21 − 20| / sqrt(2) = 0.707, |20.9 − 20.5| / sqrt(2) = 0.283
    assert notes[1] == "PSNR spread (max − min over models): 1 + 1 1.000 (sd 0.707), 3 + 1 0.400 (sd 0.283)."
    assert ablation.spread_notes([seed0], labels, ["seed 0"]) == []
    frame = ablation.per_model_frame([seed0, seed1], labels, ["seed 0", "seed 1"])
    assert len(frame) == 12 and list(frame.columns) == ["model", "row", "metric", "value"]
    assert frame.iloc[0].tolist() == ["seed 0", "1 + 1", "PSNR", 20.0]


def test_geometry_ordering_compares_both_with_none_per_model() -> None:
    seed0 = {
        "none": {"psnr": 20.0, "ssim": 0.70, "lpips": 0.20, "targets": 8.0},
        "both": {"psnr": 20.3, "ssim": 0.69, "lpips": 0.18, "targets": 8.0},
    }
    seed1 = {
        "none": {"psnr": 21.0, "ssim": 0.74, "lpips": 0.22, "targets": 8.0},
        "both": {"psnr": 20.8, "ssim": 0.75, "lpips": 0.21, "targets": 8.0},
    }
    frame = ablation.geometry_frame(ablation.mean_over_models([seed0, seed1]))
    assert frame["variant"].tolist() == ["none", "both"]
    ordering = ablation.ordering_geometry(frame, [seed0, seed1])
    # means by hand: PSNR none 20.5, both 20.55; gains +0.3 (seed 0) and -0.2 (seed 1)
    assert ordering[3] == (
        "PSNR: Both vs None better (20.5500 vs 20.5000; gain per model +0.3000, -0.2000, better in 1 of 2,"
        " mean gain within the seed spread (1.0000); paper: better)"
    )
    # SSIM: -0.01 and +0.01, mean tie 0.72 vs 0.72 -> not better; LPIPS lower is better: +0.02, +0.01
    assert ordering[4].startswith("SSIM: Both vs None not better (0.7200 vs 0.7200;")
    assert "gain per model +0.0200, +0.0100, better in 2 of 2" in ordering[5]
    assert len(ablation.ordering_geometry(frame.iloc[:1])) == 3  # without Both there is no Both-vs-None line


def test_geometry_variants_parse_in_the_papers_order() -> None:
    assert [v.key for v in ablation.parse_variants("both, none")] == ["none", "both"]
    assert ablation.parse_variants(None) == ablation.GEOMETRY_VARIANTS
    with pytest.raises(UsageError, match="variant 'depth' is unknown") as error:
        ablation.parse_variants("none,depth")
    assert error.value.one_line().startswith("--variants")
    with pytest.raises(UsageError, match="no geometry variant given"):
        ablation.parse_variants(" , ")
