"""FID / KID in a leaderboard (issue 41): which distribution rows a table uses (one per method and group, one
set of Inception weights), their cells in the group blocks, the groups whose targets have no ground truth
(novel trajectories: scored by FID / KID only), and the caption lines that say so."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from setdiff_bench.loaders.common import natural_key
from setdiff_bench.protocols import Block
from setdiff_bench.reporting.leaderboard.columns import ALL, LeaderboardError, metric_decimals
from setdiff_bench.reporting.leaderboard.table import Leaderboard, Row

#: The distribution metrics a block shows when its runs were scored with ``--inception`` (registry names).
DISTRIBUTION_METRICS = ("fid", "kid")


def groups_without_ground_truth(frame: pd.DataFrame, metric_names: Sequence[str]) -> frozenset[str]:
    """Groups whose every row has every image metric null: targets without ground truth (novel-trajectory
    packets, ``prepare --trajectory``), which ``run`` leaves unscored.  A group with any value is not one."""
    names = [m for m in metric_names if m in frame.columns]
    if not len(frame) or not names:
        return frozenset()
    empty = frame[names].isna().all(axis=1).groupby(frame["group"]).all()
    return frozenset(str(group) for group, blind in empty.items() if blind)


def select_distribution(
    distribution: pd.DataFrame | None, dataset: str, frame: pd.DataFrame, split: str | None
) -> pd.DataFrame | None:
    """The FID / KID rows of the table's measured methods, dataset and split, one per (method, group); ``None``
    when there are none.

    Raises:
        LeaderboardError: two rows for one method and group (two scored runs of a method), or rows computed
            with different Inception weights (their values cannot share a column).
    """
    if distribution is None or not len(distribution) or not len(frame):
        return None
    dist = distribution[
        (distribution["dataset"] == dataset)
        & distribution["method"].isin(set(frame["method"]))
        & distribution["group"].isin(set(frame["group"]))
    ]
    if split is not None:
        dist = dist[dist["split"] == split]
    if not len(dist):
        return None
    duplicated = dist[dist.duplicated(["method", "group"], keep=False)]
    if len(duplicated):
        first = duplicated.iloc[0]
        runs = sorted(duplicated[duplicated["method"] == first["method"]]["run"].unique())
        raise LeaderboardError(
            f"method {first['method']!r} has FID / KID for block {first['group']!r} in {len(runs)} runs "
            f"({', '.join(runs)}); keep one run per method"
        )
    weights = dist.drop_duplicates("inception_sha256")
    if len(weights) > 1:
        shown = ", ".join(
            f"{str(sha)[:12] if isinstance(sha, str) else 'unrecorded'} ({run})"
            for sha, run in weights[["inception_sha256", "run"]].itertuples(index=False)
        )
        raise LeaderboardError(
            f"runs scored FID / KID with different Inception weights: {shown}; rescore them with one "
            "--inception file (setdiff-bench evaluate RUN --inception FILE)"
        )
    return dist.reset_index(drop=True)


def distribution_cells(row: Row, dist: pd.DataFrame, blocks: Sequence[Block]) -> None:
    """Fill ``row``'s FID / KID cells from its method's distribution rows (a null value stays out: "–");
    the count is the block's enhanced targets."""
    own = dist[dist["method"] == row.method].set_index("group")
    for block in blocks:
        if block.key == ALL or block.key not in own.index:
            continue
        record = own.loc[block.key]
        for metric in DISTRIBUTION_METRICS:
            value = record[metric]
            if pd.isna(value):
                continue
            row.values[(block.key, metric)] = float(value)
            row.decimals[(block.key, metric)] = metric_decimals(metric)
            row.counts[(block.key, metric)] = int(record["enhanced"])


def distribution_notes(board: Leaderboard, dist: pd.DataFrame | None, blind: frozenset[str]) -> list[str]:
    """The caption lines of FID / KID (what they compare, with which network) and of blocks without ground
    truth (why their image metrics show "–")."""
    notes = []
    shown = {block.key for block, metrics in board.columns if set(DISTRIBUTION_METRICS) & set(metrics)}
    if dist is not None and shown:
        first = dist.iloc[0]
        sha, name = first["inception_sha256"], first["inception_file"]
        network = (name + ", " if isinstance(name, str) else "") + (
            f"SHA-256 {sha[:12]}…" if isinstance(sha, str) else "weights not recorded"
        )
        notes.append(
            "FID / KID: each block's enhanced targets against the recorded frames its packets carry as "
            "references (each once per scene), pooled over the block's scenes; Inception-v3 pool3 features "
            f"({network}, from distribution.json). They depend on the set sizes: compare them only within a "
            "block."
        )
    shown_blind = sorted(blind & {block.key for block, _ in board.columns}, key=natural_key)
    hidden = sorted(blind - set(shown_blind), key=natural_key)
    if hidden:
        notes.append(
            f"Not in the table: {', '.join(hidden)}, whose targets have no ground truth (novel trajectories); "
            "score the runs with --inception FILE for their FID / KID."
        )
    if shown_blind:
        names = shown_blind
        notes.append(
            f"–: not computed. The targets of {', '.join(names)} have no ground truth (novel trajectories), "
            "so their image metrics are null and those blocks are scored by FID / KID (and warp error, where computed)"
            + (
                ""
                if not any(b.key == ALL for b, _ in board.columns)
                else "; the pooled block leaves them out"
            )
            + "."
        )
    return notes
