"""A run folder's file names, the key columns of its tables, and where a run puts each enhanced target:
``images/<protocol>/<group>/<scene>/<frame stem>.png``.

Declared once here for :mod:`setdiff_bench.evaluation.run` (which writes them) and every reader: the leaderboard,
grids, the demo, ablations, evaluation profiles and the ``precomputed`` enhancer (which reads a run's
``images/`` folder, or any folder in the same layout).
"""

from __future__ import annotations

from pathlib import PurePosixPath

from setdiff_bench.enhancers.base import TargetRef
from setdiff_bench.errors import PacketError
from setdiff_bench.packets.index import slug
from setdiff_bench.types import PACKET_KEY_FIELDS

IMAGES_DIR = "images"
RUN_FILE = "run.json"
ENHANCER_FILE = "enhancer.json"
FRAGMENTS_DIR = "fragments"
METRICS_FILE = "metrics.parquet"
SEQUENCES_FILE = "sequences.parquet"
MANIFEST_FILE = "manifest.json"
#: An evaluation profile's tables (:mod:`setdiff_bench.evaluation.profile_scoring`), under
#: ``<run>/profiles/<profile>/``: its own ``metrics.parquet`` (:data:`METRICS_FILE`), scene and group means,
#: the profile and its coverage notes, and (EUVS profiles) the frames whose official mask pairing differs.
PROFILES_DIR = "profiles"
SCENES_FILE = "scenes.parquet"
GROUPS_FILE = "groups.parquet"
PROFILE_FILE = "profile.json"
EUVS_COMPAT_FILE = "euvs_compat.txt"

#: The columns that name one row of a run's (or an evaluation profile's) ``metrics.parquet``, in file
#: order: where the packet comes from (the :class:`~setdiff_bench.types.PacketKey` fields but its id),
#: the target view, the packet id, the view's position in it, and the method.
KEY_COLUMNS: tuple[str, ...] = (
    *(name for name in PACKET_KEY_FIELDS if name != "packet_id"),
    "frame",
    "sensor",
    "timestamp_us",
    "packet_id",
    "view",
    "method",
)


def safe_component(text: str) -> str:
    """A scene / group / protocol name as one path component.

    Names are used as they are unless they are empty, ``.``/``..`` or contain a path separator or NUL;
    those go through the packet-id slug (runs of characters other than ``A-Za-z0-9.+-`` become ``-``).
    """
    if not text or text in {".", ".."} or "/" in text or "\\" in text or "\0" in text:
        return slug(text)
    return text


def frame_relative(frame: str) -> PurePosixPath:
    """A frame name as a relative path without its extension (``CAM_FRONT/a.jpg`` → ``CAM_FRONT/a``).

    Raises:
        PacketError: an absolute name, or one with ``..`` or empty parts (it could escape its folder).
    """
    path = PurePosixPath(frame.replace("\\", "/"))
    if not frame or path.is_absolute() or any(part in {"..", "."} for part in path.parts) or "//" in frame:
        raise PacketError(f"frame name {frame!r} is not a safe relative file name")
    return path.with_suffix("") if path.suffix else path


def image_relative(ref: TargetRef) -> str:
    """``images/<protocol>/<group>/<scene>/<frame stem>.png``, POSIX, relative to the run folder."""
    parts = [IMAGES_DIR, safe_component(ref.protocol), safe_component(ref.group), safe_component(ref.scene)]
    return str(PurePosixPath(*parts, f"{frame_relative(ref.frame)}.png"))
