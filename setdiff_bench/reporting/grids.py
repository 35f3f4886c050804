"""Qualitative image grids: one row per chosen target, columns render | each method | ground truth.

When a method's outputs are the render itself (``identity``), its column stands for both ("identity =
3DGS render") instead of repeating the same images.

Cells come from the packet store (the 3DGS render and the ground truth) and from finished runs (each
method's written 8-bit output, found through its ``metrics.parquet``).  Labels are drawn with OpenCV's
Hershey font into white bands: the column titles on top, the frame (scene / group / name) left of each
row, and, under each method cell, its PSNR against the ground truth as the run scored it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.images import quantize_uint8, read_rgb, write_png
from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.packets.store import PacketStore

FONT = cv2.FONT_HERSHEY_SIMPLEX
BAND = 22
GAP = 4


@dataclass(frozen=True)
class GridFrame:
    """A target view: its packet and position among the packet's targets."""

    packet_id: str
    view: int


def pick_frames(
    index: pd.DataFrame, count: int, *, split: str | None = "test", groups: Sequence[str] | None = None
) -> list[GridFrame]:
    """``count`` targets spread over groups (round robin, in natural group order), deterministic.

    Within a group the targets are taken from the middle of its sorted list outwards, so a grid shows
    typical frames rather than the first of each sequence.
    """
    targets = index[index["role"] == "target"]
    if split is not None:
        targets = targets[targets["split"] == split]
    if groups is not None:
        targets = targets[targets["group"].isin(list(groups))]
    by_group = {}
    for group, rows in targets.groupby("group", sort=False):
        rows = rows.sort_values(["scene", "packet_id", "view"])
        order = _middle_out(len(rows))
        by_group[group] = [
            GridFrame(str(rows.iloc[i]["packet_id"]), int(rows.iloc[i]["view"])) for i in order
        ]
    picked: list[GridFrame] = []
    names = sorted(by_group, key=natural_key)
    while len(picked) < count and any(by_group.values()):
        for name in names:
            if by_group[name] and len(picked) < count:
                picked.append(by_group[name].pop(0))
    return picked


def _middle_out(n: int) -> list[int]:
    middle = (n - 1) // 2
    order = [middle]
    for step in range(1, n):
        for candidate in (middle + step, middle - step):
            if 0 <= candidate < n and len(order) < n:
                order.append(candidate)
    return order[:n]


def put_label(canvas: np.ndarray, text: str, x: int, y: int, width: int, *, scale: float = 0.42) -> None:
    """Draw ``text`` (shortened, ending in "~", to fit ``width`` pixels) with its baseline at ``(x, y)``."""
    shown = text
    while shown and cv2.getTextSize(shown, FONT, scale, 1)[0][0] > width:
        shown = shown[:-2] + "~" if len(shown) > 2 else ""
    cv2.putText(canvas, shown, (x, y), FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)


def compose(
    cells: Sequence[Sequence[np.ndarray]],
    column_labels: Sequence[str],
    row_labels: Sequence[str],
    cell_notes: Sequence[Sequence[str]] | None = None,
    *,
    label_width: int = 150,
) -> np.ndarray:
    """Tile uint8 ``(h, w, 3)`` cells (all the same size) with labels → ``(H, W, 3)`` uint8 on white."""
    rows, cols = len(cells), len(column_labels)
    height, width = cells[0][0].shape[:2]
    note = BAND if cell_notes is not None else 0
    canvas = np.full(
        (BAND + rows * (height + note + GAP), label_width + cols * (width + GAP), 3), 255, np.uint8
    )
    for c, label in enumerate(column_labels):
        put_label(canvas, label, label_width + c * (width + GAP) + 2, BAND - 7, width - 4)
    for r in range(rows):
        top = BAND + r * (height + note + GAP)
        for line, text in enumerate(row_labels[r].split("\n")):
            put_label(canvas, text, 4, top + 16 + line * 16, label_width - 8, scale=0.38)
        for c in range(cols):
            left = label_width + c * (width + GAP)
            canvas[top : top + height, left : left + width] = cells[r][c]
            if cell_notes is not None and cell_notes[r][c]:
                put_label(canvas, cell_notes[r][c], left + 2, top + height + BAND - 7, width - 4, scale=0.38)
    return canvas


def qualitative_grid(
    store: object,
    runs: Mapping[str, str | Path],
    frames: Sequence[GridFrame],
    out: str | Path,
    *,
    cell_width: int = 256,
    metric: str = "psnr",
) -> Path:
    """Write a PNG grid: render | one column per run (label → run folder) | ground truth (a run whose
    images all equal the render replaces the render column, labelled "<run> = 3DGS render").

    Args:
        store: a :class:`~setdiff_bench.packets.store.PacketStore` (or its folder) holding the packets.
        runs: column label → finished run folder (with ``metrics.parquet``), in column order.
        frames: the targets, one row each (e.g. from :func:`pick_frames`).
        out: the PNG to write (atomically).
        cell_width: width each cell is scaled to (aspect kept).
        metric: the run's metric printed under each method cell (``""`` for none).

    Raises:
        UsageError: no frames, or a run without one of the frames.
    """
    if not frames:
        raise UsageError("no frames chosen for the grid")
    store = store if isinstance(store, PacketStore) else PacketStore(store)  # type: ignore[arg-type]
    tables = {label: _run_table(Path(folder)) for label, folder in runs.items()}
    cells, notes, labels = [], [], []
    for frame in frames:
        packet = store.load_packet(frame.packet_id, targets=[frame.view])
        gt, _ = store.load_ground_truth(frame.packet_id, targets=[frame.view])
        row_cells = [_to_uint8(packet.targets.images[0])]
        row_notes = [""]
        for label, (folder, table) in tables.items():
            key = (frame.packet_id, frame.view)
            if key not in table.index:
                raise UsageError(
                    f"run {label!r} has no result for {packet.scene}/{packet.targets.names[0]} "
                    f"(packet {frame.packet_id})",
                    folder,
                )
            record = table.loc[key]
            row_cells.append(quantize_uint8(read_rgb(folder / record["image"])))
            value = record.get(metric) if metric else None
            row_notes.append(
                f"{metric.upper()} {value:.2f}" if value is not None and np.isfinite(value) else ""
            )
        row_cells.append(_to_uint8(gt[0]))
        row_notes.append("")
        cells.append(_resized(row_cells, cell_width))
        notes.append(row_notes)
        labels.append(f"{packet.scene}\n{packet.group}\n{packet.targets.names[0]}")
    columns = ["3DGS render", *runs, "ground truth"]
    same = [j for j in range(1, len(columns) - 1) if all(np.array_equal(row[0], row[j]) for row in cells)]
    if same:  # a method that returns the render (identity): one column for both, not two identical ones
        columns[same[0]] = f"{columns[same[0]]} = 3DGS render"
        columns, cells, notes = columns[1:], [row[1:] for row in cells], [row[1:] for row in notes]
    sizes = {cell.shape for row in cells for cell in row}
    if len(sizes) > 1:  # rows of different aspect ratios: pad to the largest
        height = max(s[0] for s in sizes)
        cells = [
            [np.pad(c, ((0, height - c.shape[0]), (0, 0), (0, 0)), constant_values=255) for c in row]
            for row in cells
        ]
    grid = compose(cells, columns, labels, notes if metric else None)
    write_png(out, grid)
    return Path(out)


def _run_table(folder: Path) -> tuple[Path, pd.DataFrame]:
    path = folder / METRICS_FILE
    if not path.is_file():
        raise UsageError("not a finished run (no metrics.parquet)", folder)
    return folder, pd.read_parquet(path).set_index(["packet_id", "view"])


def _to_uint8(image: object) -> np.ndarray:
    return quantize_uint8(image.permute(1, 2, 0).numpy())  # type: ignore[attr-defined]


def _resized(cells: list[np.ndarray], width: int) -> list[np.ndarray]:
    """Cells scaled to ``width`` (aspect kept): area averaging down, nearest neighbour up (pixels stay visible)."""
    h, w = cells[0].shape[:2]
    if w == width:
        return cells
    size = (width, max(1, round(h * width / w)))
    interpolation = cv2.INTER_AREA if w > width else cv2.INTER_NEAREST
    return [cv2.resize(cell, size, interpolation=interpolation) for cell in cells]
