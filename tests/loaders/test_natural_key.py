"""``natural_key``: the one natural sort (loader frame/scene order, leaderboard groups, grids)."""

from __future__ import annotations

from setdiff_bench.loaders.common import natural_key


def test_numbers_sort_numerically() -> None:
    assert sorted(["n12", "n6", "n3"], key=natural_key) == ["n3", "n6", "n12"]
    assert sorted(["12-13s", "10-11s", "11-12s"], key=natural_key) == ["10-11s", "11-12s", "12-13s"]
    assert sorted(["trav_11", "trav_6", "holdout8"], key=natural_key) == ["holdout8", "trav_6", "trav_11"]
    assert sorted(["frame_10.png", "frame_9.png", "frame_100.png"], key=natural_key) == [
        "frame_9.png",
        "frame_10.png",
        "frame_100.png",
    ]


def test_zero_padding_ties_break_on_the_text() -> None:
    # equal numbers: the plain string decides, so the order is total whatever the input order
    assert sorted(["n3", "n03"], key=natural_key) == sorted(["n03", "n3"], key=natural_key) == ["n03", "n3"]


def test_leaderboard_and_grids_use_the_loaders_key() -> None:
    from setdiff_bench.reporting import grids
    from setdiff_bench.reporting.leaderboard import aggregate

    assert aggregate.natural_key is natural_key and grids.natural_key is natural_key
