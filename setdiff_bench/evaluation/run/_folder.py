"""The run folder: refusing a folder that holds another run, claiming it, and finding what is done.

A folder is claimed by creating ``run.json`` (:func:`claim_folder`, lock-free by hard link) right before
the first results are written; a packet is done when its fragment (:func:`fragment_path`) exists.
``enhancer.json`` records the built enhancer; temporary files of killed writes are removed at merge time.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path
from typing import Any

from setdiff_bench.enhancers.base import Enhancer
from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.run._settings import jsonable_options
from setdiff_bench.io.atomic import is_stale_temporary, private_temporary, write_text_atomic
from setdiff_bench.io.names import safe_component
from setdiff_bench.io.run_layout import ENHANCER_FILE, FRAGMENTS_DIR, IMAGES_DIR, RUN_FILE


def fragment_path(out: Path, packet_id: str) -> Path:
    return out / FRAGMENTS_DIR / f"{safe_component(packet_id)}.parquet"


def check_folder(out: Path, identity: dict[str, Any]) -> None:
    """Refuse, without writing anything, a folder that holds another run or other files."""
    if not out.exists():
        return
    if not out.is_dir():
        raise UsageError("output path exists and is not a folder; choose another --out", out)
    if (out / RUN_FILE).is_file():
        _compare_settings(out, identity)
    elif _has_visible_files(out):
        raise UsageError("output folder is not empty and holds no run.json; choose another --out", out)


def claim_folder(out: Path, identity: dict[str, Any]) -> None:
    """Create ``out`` with ``run.json``, or check that the run already there has the same settings.

    Lock-free: ``run.json`` is written to a private temporary file and hard-linked into place, which
    fails if the file exists (atomic on local and network filesystems), so shards started together into
    a new folder agree on one ``run.json``, and a shard with other settings is refused.
    """
    out.mkdir(parents=True, exist_ok=True)
    run_file = out / RUN_FILE
    if not run_file.is_file():
        with private_temporary(run_file) as tmp:
            tmp.write_text(json.dumps(identity, indent=2, sort_keys=True) + "\n")
            with contextlib.suppress(FileExistsError):
                os.link(tmp, run_file)
    _compare_settings(out, identity)


def _compare_settings(out: Path, identity: dict[str, Any]) -> None:
    run_file = out / RUN_FILE
    try:
        existing = json.loads(run_file.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise UsageError(f"unreadable run settings ({error})", run_file) from None
    if existing != identity:
        changed = sorted(k for k in set(existing) | set(identity) if existing.get(k) != identity.get(k))
        if changed == ["model_files"]:
            before = "were not recorded (an older run.json)" if "model_files" not in existing else "differ"
            raise UsageError(
                f"this folder holds a run made with other model files (their SHA-256 {before}): "
                "its results would mix two models; choose another --out",
                out,
            )
        raise UsageError(
            f"this folder holds a run with other settings ({', '.join(changed)} differ); "
            "resume with the same command or choose another --out",
            out,
        )


def claimed_label(run_file: Path) -> str | None:
    """The name a claimed run's rows carry (``run.json``'s ``name`` when the run was given one, else its
    ``method``), or ``None`` when the file cannot be read (being written, damaged) or names neither."""
    try:
        identity = json.loads(run_file.read_text(encoding="utf-8"))
        label = identity.get("name", identity.get("method"))
    except (OSError, ValueError, AttributeError):
        return None
    return label if isinstance(label, str) else None


def _has_visible_files(folder: Path) -> bool:
    """Anything but hidden entries (the lock file, temporary files of killed writes)."""
    return any(not entry.name.startswith(".") for entry in folder.iterdir())


def record_enhancer(out: Path, enhancer: Enhancer) -> None:
    info = {
        "name": enhancer.name,
        "class": f"{type(enhancer).__module__}.{type(enhancer).__qualname__}",
        "options": jsonable_options(dict(getattr(enhancer, "options", {}) or {})),
    }
    path = out / ENHANCER_FILE
    text = json.dumps(info, indent=2, sort_keys=True) + "\n"
    if not path.is_file() or path.read_text() != text:
        write_text_atomic(path, text)


def remove_stale_temporaries(out: Path) -> None:
    """Temporary files of writes killed mid-way (``.<name>.<writer>.<random>.tmp<ext>``), not those of
    another shard's write in progress (:func:`~setdiff_bench.io.atomic.is_stale_temporary`)."""
    for folder in (out / IMAGES_DIR, out / FRAGMENTS_DIR, out):
        if folder.is_dir():
            pattern = "**/.*.tmp*" if folder.name == IMAGES_DIR else ".*.tmp*"
            for stale in folder.glob(pattern):
                with contextlib.suppress(FileNotFoundError):
                    if stale.is_file() and is_stale_temporary(stale):
                        stale.unlink()
