"""A training run's JSON-lines records in its output folder (``train_log.jsonl``, ``validation.jsonl``,
``samples.jsonl``; names in :mod:`.files`): appending a record, dropping the records after a resumed
checkpoint's step, and the newest validation record."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.models.setdiff.files import VALIDATION_FILE


def last_validation(out: Path) -> dict[str, float] | None:
    """The newest record of ``out``'s ``validation.jsonl`` (``None`` when no validation ran).

    The manifest's ``"validation"`` comes from here when a session scored nothing itself (a no-op rerun of
    a finished run, an interruption between two validations), so it keeps the scores the file holds.
    """
    path = out / VALIDATION_FILE
    if not path.is_file():
        return None
    last = None
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line torn by a kill
        if isinstance(record, dict):
            last = record
    return last


def truncate_records(path: Path, last_step: int) -> None:
    """Keep the records of ``path`` up to ``last_step`` (and drop a line torn by a kill), atomically."""
    if not path.is_file():
        return
    kept = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(record, dict) and int(record.get("step", 0)) <= last_step:
            kept.append(line)
    write_text_atomic(path, "".join(line + "\n" for line in kept))


def append_record(path: Path, record: dict[str, Any]) -> None:
    """Append ``record`` to the JSON-lines file ``path`` (sorted keys; the folder is created)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", encoding="utf-8") as handle:
        handle.write(json.dumps(record, sort_keys=True) + "\n")
