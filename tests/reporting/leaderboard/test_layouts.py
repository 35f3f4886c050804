"""Leaderboard table shapes come from the ``[leaderboard]`` table of each dataset's default protocol.

The expected values are hand-written from the ``LAYOUTS`` dict that ``leaderboard.py`` held before the
protocol files declared them, so the tables keep their blocks, captions and reported rows.
"""

from __future__ import annotations

from setdiff_bench.protocols import load_protocol
from setdiff_bench.reporting.leaderboard import ALL, Block, Layout, dataset_layout, reported_for


def test_euvs_layout_is_the_papers_table_1():
    assert dataset_layout("euvs") == Layout(
        (Block("level1", "Setting 1"), Block("level2", "Setting 2"), Block("level3", "Setting 3")),
        metrics=("psnr", "ssim", "lpips"),
        sequence_metrics=(),
        reported_tables=("table1_euvs",),
        title="EUVS novel-view settings (paper Table 1)",
    )


def test_nuscenes_layout_is_one_pooled_block_with_warp_error():
    assert dataset_layout("nuscenes") == Layout(
        (Block(ALL, "All"),),
        metrics=("psnr", "ssim", "lpips"),
        sequence_metrics=("warp",),
        reported_tables=("table3_nuscenes", "supp_consistency"),
        title="nuScenes temporal extrapolation, 10-15 s (paper Table 3 and consistency table)",
    )


def test_paralane_dl3dv_synthetic_layouts():
    assert dataset_layout("paralane") == Layout(
        (Block("single", "Single-lane shift"), Block("double", "Double-lane shift")),
        reported_tables=("table2_paralane",),
        title="Para-Lane lane shifts (paper Table 2)",
    )
    assert dataset_layout("dl3dv") == Layout(
        (Block("n3", "3 views"), Block("n6", "6 views"), Block("n9", "9 views")),
        reported_tables=("table4_dl3dv",),
        title="DL3DV sparse views (paper Table 4)",
    )
    assert dataset_layout("synthetic") == Layout(
        (
            Block("lane+1", "Lane +1"),
            Block("lane+2", "Lane +2"),
            Block("side", "Side cameras"),
            Block("turn", "Turn"),
            Block("interp", "Held-out"),
        ),
        title="Synthetic streets (fit on lane 0, front camera)",
    )


def test_datasets_without_a_leaderboard_table_get_one_block_per_group():
    for dataset in ("colmap", "nerfstudio", "waymo"):
        assert dataset_layout(dataset) == Layout(None)
    assert load_protocol("nuscenes_drivestudio").leaderboard is None
    assert not len(reported_for("colmap"))


def test_block_groups_are_the_protocols_groups():
    for name in ("euvs", "paralane", "dl3dv", "synthetic"):
        protocol = load_protocol(name)
        assert protocol.leaderboard is not None
        assert [b.key for b in protocol.leaderboard.blocks] == [g.name for g in protocol.groups]
