"""Same tensors and metadata give the same safetensors bytes, whatever order the writer put the metadata in."""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file

from setdiff_bench.io.safetensors_header import sort_metadata


def reorder_metadata(path: Path, order: list[str]) -> None:
    """Rewrite the header with the metadata keys in ``order`` (what another process's writer may produce)."""
    data = path.read_bytes()
    length = int.from_bytes(data[:8], "little")
    header = json.loads(data[8 : 8 + length])
    header["__metadata__"] = {key: header["__metadata__"][key] for key in order}
    text = json.dumps(header, separators=(",", ":"), ensure_ascii=False).encode()
    path.write_bytes(data[:8] + text + b" " * (length - len(text)) + data[8 + length :])


def test_metadata_order_no_longer_changes_the_bytes(tmp_path: Path) -> None:
    tensors = {"b.weight": torch.arange(6, dtype=torch.float32).reshape(2, 3), "a.bias": torch.ones(3)}
    metadata = {"format": "setdiff-bench", "config": '{"x": 1}', "zeta": "é"}
    first, second = tmp_path / "1.safetensors", tmp_path / "2.safetensors"
    save_file(tensors, str(first), metadata=metadata)
    save_file(tensors, str(second), metadata=metadata)
    reorder_metadata(first, ["zeta", "config", "format"])
    reorder_metadata(second, ["format", "zeta", "config"])
    assert first.read_bytes() != second.read_bytes()
    sort_metadata(first)
    sort_metadata(second)
    assert first.read_bytes() == second.read_bytes()
    loaded = load_file(str(first))
    assert loaded.keys() == tensors.keys() and all(torch.equal(loaded[k], tensors[k]) for k in tensors)
    with safe_open(str(first), "pt") as handle:
        assert handle.metadata() == metadata
    header = json.loads(first.read_bytes()[8 : 8 + int.from_bytes(first.read_bytes()[:8], "little")])
    assert list(header["__metadata__"]) == sorted(metadata)
