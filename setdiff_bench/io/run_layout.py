"""A run folder's file names, the key columns of its tables, and where a run puts each enhanced target:
``images/<protocol>/<group>/<scene>/<frame stem>.png``.

Declared once here, on the I/O floor, for :mod:`setdiff_bench.evaluation.run` (which writes them) and every
reader: the leaderboard, grids, the demo, ablations, evaluation profiles and the ``precomputed`` enhancer (which
reads a run's ``images/`` folder, or any folder in the same layout).  Names become path components through
:mod:`setdiff_bench.io.names`.
"""

from __future__ import annotations

from pathlib import PurePosixPath

from setdiff_bench.io.names import frame_relative, safe_component
from setdiff_bench.types import PACKET_KEY_FIELDS, TargetRef

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


#: The columns that name one target within a dataset, as its written image is named (:func:`image_relative`):
#: a run's rows are unique on them per method.
TARGET_COLUMNS: tuple[str, ...] = ("protocol", "group", "scene", "frame")


def image_relative(ref: TargetRef) -> str:
    """``images/<protocol>/<group>/<scene>/<frame stem>.png``, POSIX, relative to the run folder."""
    parts = [IMAGES_DIR, safe_component(ref.protocol), safe_component(ref.group), safe_component(ref.scene)]
    return str(PurePosixPath(*parts, f"{frame_relative(ref.frame)}.png"))
