"""Byte-identical safetensors files: the writer stores ``__metadata__`` in a Rust ``HashMap``, whose
order is random per process, so the same tensors and metadata gave different file bytes (measured:
the tiny DiFix checkpoint alternated between two hashes).  :func:`sort_metadata` rewrites the header
in place with the metadata keys sorted; tensors and offsets are untouched.
"""

from __future__ import annotations

import json
import os

_LENGTH_BYTES = 8  # little-endian u64 header length, then the JSON header, then the tensor data


def sort_metadata(path: str | os.PathLike[str]) -> None:
    """Sort the ``__metadata__`` keys of the safetensors file ``path`` in place (same header length)."""
    with open(path, "r+b") as handle:
        length = int.from_bytes(handle.read(_LENGTH_BYTES), "little")
        raw = handle.read(length)
        header = json.loads(raw)
        metadata = header.get("__metadata__")
        if not metadata or len(metadata) < 2:
            return
        ordered = {"__metadata__": dict(sorted(metadata.items()))}
        ordered.update((key, value) for key, value in header.items() if key != "__metadata__")
        text = json.dumps(ordered, separators=(",", ":"), ensure_ascii=False).encode("utf-8")
        if len(text) > length:  # another JSON spelling than the writer's: leave the file as it is
            return
        handle.seek(_LENGTH_BYTES)
        handle.write(text + b" " * (length - len(text)))  # the format pads headers with spaces
