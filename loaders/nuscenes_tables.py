"""nuScenes JSON tables: reading one, checking the types of the fields the loader reads (rounding fractional
microsecond timestamps, with one warning per table), and looking records up by token with errors that name the
referring file.  Used by :mod:`.nuscenes`, which assembles the camera frames; dataset facts in docs/datasets.md.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from setdiff_bench.errors import DatasetError, DatasetWarning

from .common import read_json


def load_table(tables: Path, name: str) -> list[dict[str, Any]]:
    """One table as a list of records.

    Raises:
        DatasetError: missing file, invalid JSON, not a list of objects with a ``token``.
    """
    path = tables / f"{name}.json"
    if not path.is_file():
        raise DatasetError(f"missing nuScenes table {name}.json", path)
    records = read_json(path, "table")
    if not isinstance(records, list) or not all(
        isinstance(r, dict) and isinstance(r.get("token"), str) for r in records
    ):
        raise DatasetError("expected a JSON list of records with a string 'token' field", path)
    return records


_TOKEN = (str,)
_LIST = (list,)
#: Types of the fields this loader reads, per table (checked when present; ``bool`` is not an ``int`` here).
FIELD_TYPES: dict[str, dict[str, tuple[type, ...]]] = {
    "scene": {"name": (str,), "first_sample_token": _TOKEN, "log_token": _TOKEN, "description": (str,)},
    "sample": {"scene_token": _TOKEN, "next": _TOKEN, "prev": _TOKEN},
    "sample_data": {
        "sample_token": _TOKEN,
        "ego_pose_token": _TOKEN,
        "calibrated_sensor_token": _TOKEN,
        "timestamp": (int,),
        "is_key_frame": (bool,),
        "filename": (str,),
        "width": (int,),
        "height": (int,),
        "prev": _TOKEN,
        "next": _TOKEN,
    },
    "calibrated_sensor": {
        "sensor_token": _TOKEN,
        "rotation": _LIST,
        "translation": _LIST,
        "camera_intrinsic": _LIST,
    },
    "sensor": {"channel": (str,), "modality": (str,)},
    "ego_pose": {"rotation": _LIST, "translation": _LIST},
    "log": {"location": (str,), "logfile": (str,)},
}


#: Fields stored in integer microseconds that may be written as fractional floats; rounded on load.
MICROSECOND_FIELDS: dict[str, tuple[str, ...]] = {"sample_data": ("timestamp",)}


def check_field_types(record: dict[str, Any], table: str, path: Path) -> int:
    """Raise ``DatasetError`` when a field the loader reads has another JSON type than the schema's.

    An integral float where the schema has an int (``1556675185850000.0``: nuScenes-format tables
    written by other tools, e.g. Lyft tables trimmed by mmdetection3d) is accepted and stored as the int.
    A finite non-integral float in a microsecond field (:data:`MICROSECOND_FIELDS`,
    ``1556675185903083.2``) is rounded to the nearest microsecond and stored as the int; NaN and
    infinities stay refused.

    Returns:
        how many fields of ``record`` were rounded (the caller warns once per table with the total).
    """
    rounded = 0
    for field, kinds in FIELD_TYPES.get(table, {}).items():
        if field not in record:
            continue
        value = record[field]
        if int in kinds and isinstance(value, float) and value.is_integer():
            record[field] = value = int(value)
        elif field in MICROSECOND_FIELDS.get(table, ()) and isinstance(value, float) and math.isfinite(value):
            record[field] = value = round(value)
            rounded += 1
        if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
            expected = " or ".join("list" if k is list else k.__name__ for k in kinds)
            raise DatasetError(
                f"{table} {record['token']!r} field {field!r} must be a JSON {expected}, got {value!r:.60}",
                path,
            )
    return rounded


@dataclass
class Table:
    """Records of one table by token, with its file for error messages."""

    name: str
    path: Path
    rows: dict[str, dict[str, Any]]

    @classmethod
    def load(cls, tables: Path, name: str) -> Table:
        rows: dict[str, dict[str, Any]] = {}
        path = tables / f"{name}.json"
        rounded = 0
        for record in load_table(tables, name):
            if record["token"] in rows:
                raise DatasetError(f"duplicate token {record['token']!r}", path)
            rounded += check_field_types(record, name, path)
            rows[record["token"]] = record
        if rounded:
            fields = " / ".join(MICROSECOND_FIELDS[name])
            warnings.warn(
                f"{path}: {rounded} {name} {fields} values are fractional microseconds; "
                "rounded to the nearest microsecond",
                DatasetWarning,
                stacklevel=2,
            )
        return cls(name, path, rows)

    def get(self, token: Any, referrer: Table, referrer_token: str, field: str) -> dict[str, Any]:
        """The record ``token`` names; a dangling token is a ``DatasetError`` naming the referring file."""
        record = self.rows.get(token) if isinstance(token, str) else None
        if record is None and field not in referrer.rows.get(referrer_token, {}):
            raise DatasetError(f"{referrer.name} {referrer_token!r}: missing field {field!r}", referrer.path)
        if record is None:
            raise DatasetError(
                f"{referrer.name} {referrer_token!r} field {field!r} refers to token {token!r}, "
                f"which is not in {self.name}.json",
                referrer.path,
            )
        return record
