"""Standard 3DGS PLY: round trip, the Inria layout written by hand, ASCII, and malformed files."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from setdiff_bench.errors import PlyError
from setdiff_bench.gaussians.ply import read_ply, write_ply
from tests.gaussians.gaussian_fixtures import ply_header, ply_property_names, random_model


@pytest.mark.parametrize("degree", [0, 1, 3])
@pytest.mark.parametrize("normals", [True, False])
def test_round_trip_bit_exact(tmp_path: Path, degree: int, normals: bool) -> None:
    model = random_model(degree=degree)
    write_ply(tmp_path / "m.ply", model, normals=normals)
    back = read_ply(tmp_path / "m.ply")
    for name, value in model.tensors().items():
        assert torch.equal(getattr(back, name), value), name


def inria_ply_bytes(xyz, f_dc, f_rest, opacity, scale, rot) -> bytes:
    """The layout of graphdeco-inria gaussian_model.save_ply, written independently with numpy."""
    n = xyz.shape[0]
    names = ply_property_names(f_rest.shape[1], normals=True)
    dtype = [(name, "<f4") for name in names]
    table = np.concatenate([xyz, np.zeros_like(xyz), f_dc, f_rest, opacity, scale, rot], axis=1)
    elements = np.empty(n, dtype=dtype)
    elements[:] = list(map(tuple, table))
    return ply_header("binary_little_endian", n, names).encode() + elements.tobytes()


def test_reads_inria_layout_written_by_hand(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    n = 7
    xyz = rng.normal(size=(n, 3)).astype(np.float32)
    f_dc = rng.normal(size=(n, 3)).astype(np.float32)
    # Inria: features_rest (N, 15, 3) transposed to (N, 3, 15) and flattened → channel-major
    rest = rng.normal(size=(n, 15, 3)).astype(np.float32)
    f_rest = rest.transpose(0, 2, 1).reshape(n, 45)
    opacity = rng.normal(size=(n, 1)).astype(np.float32)
    scale = rng.normal(size=(n, 3)).astype(np.float32)
    rot = rng.normal(size=(n, 4)).astype(np.float32)
    (tmp_path / "inria.ply").write_bytes(inria_ply_bytes(xyz, f_dc, f_rest, opacity, scale, rot))
    model = read_ply(tmp_path / "inria.ply")
    assert model.sh_degree == 3
    assert np.array_equal(model.means.numpy(), xyz)
    assert np.array_equal(model.sh[:, 0].numpy(), f_dc)
    assert np.array_equal(model.sh[:, 1:].numpy(), rest)
    assert np.array_equal(model.opacity_logits.numpy(), opacity[:, 0])
    assert np.array_equal(model.log_scales.numpy(), scale)
    assert np.array_equal(model.quats.numpy(), rot)


def test_reads_ascii(tmp_path: Path) -> None:
    header = ply_header("ascii", 2, ply_property_names())
    rows = ["1 2 3 0.1 0.2 0.3 -1 -2 -2 -2 1 0 0 0", "4 5 6 0 0 0 2 -1 -1 -1 0 1 0 0"]
    (tmp_path / "a.ply").write_text(header + "\n".join(rows) + "\n")
    model = read_ply(tmp_path / "a.ply")
    assert model.means.tolist() == [[1, 2, 3], [4, 5, 6]]
    assert model.sh_degree == 0
    assert model.opacity_logits.tolist() == [-1, 2]


def test_malformed_files(tmp_path: Path) -> None:
    model = random_model(degree=1)
    write_ply(tmp_path / "ok.ply", model)
    raw = (tmp_path / "ok.ply").read_bytes()
    cases = {
        "truncated.ply": (raw[:-10], "only"),
        "extra.ply": (raw + b"\0" * 62 * 4 * 2, "after"),
        "nomagic.ply": (b"plz" + raw[3:], "magic"),
        "missing.ply": (raw.replace(b"property float opacity\n", b"property float opacityX\n"), "opacity"),
        "rest.ply": (raw.replace(b"property float f_rest_8\n", b"property float g_rest_8\n"), "f_rest"),
    }
    for name, (data, match) in cases.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(PlyError, match=match) as info:
            read_ply(tmp_path / name)
        assert name in str(info.value)
    bad = random_model(degree=0)
    bad.means[3, 1] = float("nan")
    write_ply(tmp_path / "nan.ply", bad)
    with pytest.raises(PlyError, match="NaN"):
        read_ply(tmp_path / "nan.ply")
