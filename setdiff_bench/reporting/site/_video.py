"""Side-by-side videos: render | method | ground truth, one per target sequence, camera and method.

A sequence is the ordered targets of one camera: for the time-ordered protocols (nuScenes, where a
camera's targets span several time-offset groups) every target of a (scene, sensor), across groups, by
timestamp — the sequences the runs' warp error uses; elsewhere the targets of a (scene, group, sensor)
trajectory, by timestamp when every target has one, then by frame name.

Format: WebM with VP9 (OpenCV's FFmpeg writer, fourcc ``VP90``), which Chromium, Firefox and Safari play
without plug-ins; H.264 is not offered by the OpenCV wheels (no encoder), and the MPEG-4 Part 2 they
write is not played by Chromium.  Frame sides are padded to even numbers (4:2:0 chroma).

Each video has a poster, ``<video name>.jpg``: its first frame, which a page shows before the video plays
(without one a browser that only loads the metadata paints the player black until it is played).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pandas as pd

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.evaluation.run import SEQUENCE_PROTOCOLS
from setdiff_bench.io.atomic import atomic_path
from setdiff_bench.io.native_stderr import native_stderr_silenced
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.reporting.grids import compose
from setdiff_bench.reporting.site._pictures import write_jpeg
from setdiff_bench.reporting.site._settings import DEFAULT_PANEL_WIDTH
from setdiff_bench.reporting.targets import TargetImages, TargetKey

VIDEO_SUFFIX = ".webm"
POSTER_SUFFIX = ".jpg"
FOURCC = "VP90"


class VideoError(SetDiffBenchError):
    """A video that cannot be written (no encoder, no frames)."""


@dataclass(frozen=True)
class TargetSequence:
    """The ordered targets of one camera.

    Attributes:
        dataset, scene, sensor: where the camera is.
        group: the protocol group (``""`` for a time-ordered sequence across groups).
        targets: the targets in display order.
    """

    dataset: str
    scene: str
    group: str
    sensor: str
    targets: tuple[TargetKey, ...]

    @property
    def title(self) -> str:
        """``scene / group / sensor`` (the group left out when the sequence spans groups)."""
        return " / ".join(part for part in (self.scene, self.group, self.sensor) if part)

    @property
    def slug(self) -> str:
        """A file-name-safe name, unique among the sequences of one report."""
        return slug("__".join(part for part in (self.dataset, self.scene, self.group, self.sensor) if part))


def slug(text: str) -> str:
    """``text`` with every character other than letters, digits, ``.``, ``_``, ``-`` and ``+`` replaced by ``-``."""
    return re.sub(r"[^A-Za-z0-9._+-]", "-", text)


def target_sequences(rows: pd.DataFrame) -> list[TargetSequence]:
    """The camera sequences of the targets in ``rows`` (a run's ``metrics.parquet`` rows: ``dataset,
    protocol, group, scene, sensor, frame, timestamp_us, packet_id, view``), in natural order of
    (dataset, scene, group, sensor)."""
    if rows.empty:
        return []
    frame = rows.drop_duplicates(["packet_id", "view"]).copy()
    frame["_group"] = np.where(frame["protocol"].isin(SEQUENCE_PROTOCOLS), "", frame["group"])
    sequences = []
    for (dataset, scene, group, sensor), members in frame.groupby(
        ["dataset", "scene", "_group", "sensor"], sort=False, dropna=False
    ):
        timed = members["timestamp_us"].notna().all()
        order = sorted(
            members.itertuples(index=False),
            key=lambda r: (
                float(r.timestamp_us) if timed else 0.0,
                natural_key(str(r.frame)),
                str(r.packet_id),
                int(r.view),
            ),
        )
        keys = tuple(TargetKey(str(r.packet_id), int(r.view)) for r in order)
        sequences.append(TargetSequence(str(dataset), str(scene), str(group), str(sensor), keys))
    return sorted(
        sequences,
        key=lambda s: (s.dataset, natural_key(s.scene), natural_key(s.group), natural_key(s.sensor)),
    )


def _even(image: np.ndarray) -> np.ndarray:
    height, width = image.shape[:2]
    return np.pad(image, ((0, height % 2), (0, width % 2), (0, 0)), constant_values=255)


def write_video(path: str | Path, frames: Iterable[np.ndarray], fps: float = 4.0) -> Path:
    """Write 8-bit RGB frames (all the same size) as a VP9 WebM, atomically.

    Raises:
        VideoError: no frames, frames of different sizes, or no VP9 encoder in this OpenCV.
    """
    path = Path(path)
    iterator = iter(frames)
    first = next(iterator, None)
    if first is None:
        raise VideoError("no frames to write", path)
    first = _even(first)
    height, width = first.shape[:2]
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        with native_stderr_silenced():
            writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*FOURCC), fps, (width, height))
        if not writer.isOpened():
            raise VideoError("this OpenCV build cannot write VP9/WebM video (no FFmpeg VP9 encoder)", path)
        try:
            for frame in [first, *(_even(f) for f in iterator)]:
                if frame.shape[:2] != (height, width):
                    raise VideoError(f"frame of size {frame.shape[:2]} in a video of {(height, width)}", path)
                writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
        finally:
            writer.release()
    return path


def _panel(image: np.ndarray, width: int | None) -> np.ndarray:
    height, columns = image.shape[:2]
    if width is None or columns <= width:
        return image
    size = (width, max(1, round(height * width / columns)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def side_by_side(
    render: np.ndarray,
    output: np.ndarray,
    truth: np.ndarray,
    method: str,
    caption: str,
    panel_width: int | None = None,
) -> np.ndarray:
    """One video frame: render | method | ground truth with a title band, and ``caption`` (the frame)
    on the left; panels wider than ``panel_width`` are scaled down (area averaging; ``None``: as given)."""
    render, output, truth = (_panel(image, panel_width) for image in (render, output, truth))
    return compose(
        [[render, output, truth]],
        ["3DGS render", method, "ground truth"],
        [caption],
        label_width=0 if not caption else 48,
    )


@dataclass(frozen=True)
class VideoRecord:
    """A written video: its sequence, the method shown, the file, its frame count and its poster (the first
    frame as a JPEG beside the video)."""

    sequence: TargetSequence
    method: str
    path: Path
    frames: int
    poster: Path


def sequence_video(
    images: TargetImages,
    sequence: TargetSequence,
    method: str,
    path: str | Path,
    *,
    fps: float = 4.0,
    panel_width: int | None = DEFAULT_PANEL_WIDTH,
) -> VideoRecord:
    """Write the render | ``method`` | ground truth video of ``sequence`` to ``path`` (panels at most
    ``panel_width`` pixels wide), and its poster (the first frame) to ``path`` with the suffix ``.jpg``."""
    path = Path(path)
    poster = path.with_suffix(POSTER_SUFFIX)

    def frames() -> Iterator[np.ndarray]:
        for number, key in enumerate(sequence.targets):
            frame = side_by_side(
                images.render(key),
                images.output(method, key),
                images.ground_truth(key),
                method,
                f"{number + 1}/{len(sequence.targets)}",
                panel_width,
            )
            if number == 0:
                write_jpeg(poster, frame)
            yield frame

    write_video(path, frames(), fps)
    return VideoRecord(sequence, method, path, len(sequence.targets), poster)


def write_videos(
    images: TargetImages,
    sequences: Sequence[TargetSequence],
    methods: Sequence[str],
    folder: str | Path,
    *,
    fps: float = 4.0,
    min_frames: int = 2,
    panel_width: int | None = DEFAULT_PANEL_WIDTH,
) -> list[VideoRecord]:
    """One video per sequence (of at least ``min_frames`` targets) and method, named
    ``<sequence slug>__<method>.webm`` in ``folder``, each with its poster ``<same name>.jpg``."""
    records = []
    for sequence in sequences:
        if len(sequence.targets) < min_frames:
            continue
        for method in methods:
            path = Path(folder) / f"{sequence.slug}__{slug(method)}{VIDEO_SUFFIX}"
            records.append(sequence_video(images, sequence, method, path, fps=fps, panel_width=panel_width))
    return records
