"""The images of one target as a report shows them: the 3DGS render and the ground truth (from the packet
store), each run's written output (through its ``metrics.parquet``), and error maps ``|method − GT|``.

Shared by the HTML site (:mod:`setdiff_bench.reporting.site`) and its videos, so both show the same pixels.
Every image is 8-bit RGB
``(H, W, 3)``; files are checked against the store's SHA-256 on read (:meth:`PacketStore.file_path`).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.images import quantize_uint8, read_rgb
from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.packets.store import PacketStore

#: Absolute error (0–1 scale, mean over RGB) shown as the brightest colour of an error map.
ERROR_MAP_FULL_SCALE = 0.25
#: Renders and ground truths kept in memory by :class:`TargetImages` (least recently read dropped first).
CACHED = 512


@dataclass(frozen=True)
class TargetKey:
    """A target view: its packet and position among the packet's targets."""

    packet_id: str
    view: int


class TargetImages:
    """Reads the render, ground truth and each run's output of targets.

    Args:
        store: the packet store the runs were made on.
        runs: method label → finished run folder (with ``metrics.parquet``).
        max_width: images wider than this are scaled down (area averaging) for display; ``None`` keeps them.

    Raises:
        UsageError: a run folder without ``metrics.parquet``.
    """

    def __init__(
        self, store: PacketStore, runs: Mapping[str, str | Path], *, max_width: int | None = None
    ) -> None:
        self.store = store
        self.max_width = max_width
        self.runs = {label: Path(folder) for label, folder in runs.items()}
        self._tables: dict[str, pd.DataFrame] = {}
        self._cache: OrderedDict[tuple[str, TargetKey], np.ndarray] = OrderedDict()
        for label, folder in self.runs.items():
            path = folder / METRICS_FILE
            if not path.is_file():
                raise UsageError("not a finished run (no metrics.parquet)", folder)
            self._tables[label] = pd.read_parquet(path, columns=["packet_id", "view", "image"]).set_index(
                ["packet_id", "view"]
            )

    def _row(self, key: TargetKey) -> pd.Series:
        rows = self.store.rows(key.packet_id)
        match = rows[(rows["role"] == "target") & (rows["view"].astype(int) == key.view)]
        if match.empty:
            raise UsageError(f"packet {key.packet_id!r} has no target {key.view}", self.store.root)
        return match.iloc[0]

    def _display(self, image: np.ndarray) -> np.ndarray:
        height, width = image.shape[:2]
        if self.max_width is None or width <= self.max_width:
            return image
        size = (self.max_width, max(1, round(height * self.max_width / width)))
        return cv2.resize(image, size, interpolation=cv2.INTER_AREA)

    def _cached(self, kind: str, key: TargetKey, read: Callable[[], np.ndarray]) -> np.ndarray:
        """``read()``, remembered for the last :data:`CACHED` images (a report reads each several times)."""
        if (kind, key) not in self._cache:
            self._cache[(kind, key)] = read()
            while len(self._cache) > CACHED:
                self._cache.popitem(last=False)
        return self._cache[(kind, key)]

    def render(self, key: TargetKey) -> np.ndarray:
        """The 3DGS render the methods enhanced (the packet's target image), 8-bit."""

        def read() -> np.ndarray:
            return self._display(quantize_uint8(read_rgb(self.store.file_path(self._row(key), "image"))))

        return self._cached("render", key, read)

    def ground_truth(self, key: TargetKey) -> np.ndarray:
        """The captured image at the target camera, 8-bit."""

        def read() -> np.ndarray:
            row = self._row(key)
            size = (int(row["height"]), int(row["width"]))
            return self._display(quantize_uint8(read_rgb(self.store.file_path(row, "gt"), size)))

        return self._cached("gt", key, read)

    def output(self, label: str, key: TargetKey) -> np.ndarray:
        """Run ``label``'s written output for the target, 8-bit.

        Raises:
            UsageError: the run has no result for the target.
        """
        table = self._tables[label]
        index = (key.packet_id, key.view)
        if index not in table.index:
            raise UsageError(
                f"run {label!r} has no result for packet {key.packet_id} target {key.view}", self.runs[label]
            )
        return self._display(quantize_uint8(read_rgb(self.runs[label] / str(table.loc[index, "image"]))))


def error_map(image: np.ndarray, truth: np.ndarray, full_scale: float = ERROR_MAP_FULL_SCALE) -> np.ndarray:
    """``|image − truth|`` (mean over RGB) as an 8-bit RGB heat map (OpenCV's *inferno*): black = equal,
    the brightest colour = ``full_scale`` (0–1 scale) or more.  The same scale for every method, so maps
    compare across methods."""
    if image.shape != truth.shape:
        raise UsageError(f"image {image.shape} and ground truth {truth.shape} differ in size")
    error = np.abs(image.astype(np.float32) - truth.astype(np.float32)).mean(axis=2) / 255.0
    level = np.clip(error / full_scale, 0.0, 1.0)
    bgr = cv2.applyColorMap(np.rint(level * 255).astype(np.uint8), cv2.COLORMAP_INFERNO)
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
