"""The standard 3DGS PLY file (Inria ``gaussian_model.py`` layout; gsplat's export without normals).

Vertex properties: ``x y z [nx ny nz] f_dc_0..2 f_rest_0..(3·(K−1)−1) opacity scale_0..2 rot_0..3``,
all pre-activation; ``f_rest`` is channel-major (R coefficients 1..K−1, then G, then B).

Written by hand rather than with ``plyfile``: it is a tiny header parser plus one ``np.frombuffer``,
and owning it lets every malformed file fail with one precise line (missing property, short data,
NaN) instead of a library traceback.  Reads binary little-endian, binary big-endian and ASCII;
writes binary little-endian.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.errors import PlyError
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.io.atomic import atomic_path

_PLY_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_MAX_HEADER_BYTES = 1 << 16
_REST_NAME = re.compile(r"^f_rest_[0-9]{1,4}$")
_REQUIRED = [
    "x",
    "y",
    "z",
    "f_dc_0",
    "f_dc_1",
    "f_dc_2",
    "opacity",
    "scale_0",
    "scale_1",
    "scale_2",
    "rot_0",
    "rot_1",
    "rot_2",
    "rot_3",
]


def read_ply(path: str | os.PathLike[str]) -> GaussianModel:
    """Read a 3DGS PLY into a float32 :class:`GaussianModel` on the CPU.

    Raises:
        PlyError: not a PLY, unsupported format, missing properties, an ``f_rest`` count that is no
            SH degree, a vertex count that does not match the data, or NaN/inf values.
    """
    path = Path(path)
    if not path.is_file():
        raise PlyError("file not found", path)
    raw = path.read_bytes()
    fmt, count, props, body_offset = _parse_header(raw, path)
    names = [name for name, _ in props]
    missing = [name for name in _REQUIRED if name not in names]
    if missing:
        raise PlyError(f"missing vertex properties {', '.join(missing)}", path)
    rest_names = [n for n in names if n.startswith("f_rest_")]
    malformed = next((n for n in rest_names if not _REST_NAME.match(n)), None)
    if malformed is not None:
        raise PlyError(f"malformed property name {malformed!r} (expected f_rest_<number>)", path)
    rest = sorted(rest_names, key=lambda n: int(n[len("f_rest_") :]))
    if [int(n[len("f_rest_") :]) for n in rest] != list(range(len(rest))):
        raise PlyError("f_rest_* properties are not numbered 0..n-1", path)
    bases = len(rest) // 3 + 1
    if len(rest) % 3 or bases not in (1, 4, 9, 16):
        raise PlyError(f"{len(rest)} f_rest properties do not match any SH degree 0-3 (0, 9, 24 or 45)", path)

    if fmt == "ascii":
        columns = _read_ascii(raw[body_offset:], count, props, path)
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        dtype = np.dtype([(name, endian + kind) for name, kind in props])
        needed = dtype.itemsize * count
        available = len(raw) - body_offset
        if available < needed:
            raise PlyError(
                f"header declares {count} vertices ({needed} bytes) but only {available} bytes follow "
                f"({available // max(dtype.itemsize, 1)} vertices)",
                path,
            )
        if available > needed:
            raise PlyError(
                f"{available - needed} bytes after the {count} declared vertices "
                "(vertex count wrong, or unsupported extra elements)",
                path,
            )
        data = np.frombuffer(raw, dtype=dtype, count=count, offset=body_offset)
        columns = {name: _as_float32(data[name]) for name, _ in props}

    def stack(keys: list[str]) -> np.ndarray:
        return np.stack([columns[k] for k in keys], axis=1) if keys else np.zeros((count, 0), np.float32)

    means = stack(["x", "y", "z"])
    dc = stack(["f_dc_0", "f_dc_1", "f_dc_2"])
    f_rest = stack(rest).reshape(count, 3, bases - 1).transpose(0, 2, 1)
    sh = np.concatenate([dc[:, None, :], f_rest], axis=1)
    model = GaussianModel(
        means=torch.from_numpy(np.ascontiguousarray(means)),
        quats=torch.from_numpy(np.ascontiguousarray(stack(["rot_0", "rot_1", "rot_2", "rot_3"]))),
        log_scales=torch.from_numpy(np.ascontiguousarray(stack(["scale_0", "scale_1", "scale_2"]))),
        opacity_logits=torch.from_numpy(np.ascontiguousarray(columns["opacity"])),
        sh=torch.from_numpy(np.ascontiguousarray(sh, dtype=np.float32)),
    )
    model.check_finite(str(path))
    zero_quats = int((model.quats.norm(dim=1) == 0).sum())
    if zero_quats:
        raise PlyError(f"{zero_quats} Gaussians have an all-zero rotation quaternion", path)
    return model


def write_ply(path: str | os.PathLike[str], model: GaussianModel, *, normals: bool = True) -> None:
    """Write a binary little-endian 3DGS PLY atomically (float32; zero normals when ``normals``)."""
    m = model.detach().to("cpu", torch.float32)
    n = len(m)
    bases = m.sh.shape[1]
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals else []) + ["f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(3 * (bases - 1))]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    parts = [m.means.numpy()]
    if normals:
        parts.append(np.zeros((n, 3), np.float32))
    parts.append(m.sh[:, 0, :].numpy())
    parts.append(m.sh[:, 1:, :].permute(0, 2, 1).reshape(n, -1).numpy())
    parts += [m.opacity_logits[:, None].numpy(), m.log_scales.numpy(), m.quats.numpy()]
    table = np.ascontiguousarray(np.concatenate(parts, axis=1).astype("<f4"))
    header = "ply\nformat binary_little_endian 1.0\n"
    header += f"element vertex {n}\n" + "".join(f"property float {name}\n" for name in names) + "end_header\n"
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        handle.write(header.encode("ascii"))
        handle.write(table.tobytes())


def _parse_header(raw: bytes, path: Path) -> tuple[str, int, list[tuple[str, str]], int]:
    if not raw.startswith(b"ply"):
        raise PlyError("not a PLY file (missing 'ply' magic)", path)
    end = raw.find(b"end_header", 0, _MAX_HEADER_BYTES)
    if end < 0:
        raise PlyError("no 'end_header' in the first 64 KiB", path)
    newline = raw.find(b"\n", end)
    if newline < 0:
        raise PlyError("file ends right after 'end_header' (no vertex data)", path)
    try:
        lines = raw[:end].decode("ascii").replace("\r", "").split("\n")
    except UnicodeDecodeError as exc:
        raise PlyError("header is not ASCII", path) from exc
    fmt = ""
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if len(words) < 2 or words[1] not in ("ascii", "binary_little_endian", "binary_big_endian"):
                raise PlyError(f"unsupported format line {line.strip()!r}", path)
            fmt = words[1]
        elif words[0] == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise PlyError(f"malformed element line {line.strip()!r}", path)
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            if not elements:
                raise PlyError("property before any element", path)
            if len(words) >= 2 and words[1] == "list":
                elements[-1][2].append((words[-1], "list"))
                continue
            if len(words) != 3 or words[1] not in _PLY_TYPES:
                raise PlyError(f"malformed property line {line.strip()!r}", path)
            elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
        else:
            raise PlyError(f"unexpected header line {line.strip()!r}", path)
    if not fmt:
        raise PlyError("no format line in header", path)
    vertex = [e for e in elements if e[0] == "vertex"]
    if not vertex:
        raise PlyError("no 'element vertex' in header", path)
    if elements[0][0] != "vertex" or any(e[1] > 0 for e in elements[1:]):
        raise PlyError(
            "only a single leading vertex element is supported (other elements must be empty)", path
        )
    _, count, props = vertex[0]
    if any(kind == "list" for _, kind in props):
        raise PlyError("list properties are not supported in the vertex element", path)
    seen: set[str] = set()
    for name, _ in props:
        if name in seen:
            raise PlyError(f"duplicate property {name!r}", path)
        seen.add(name)
    return fmt, count, props, newline + 1


def _read_ascii(body: bytes, count: int, props: list[tuple[str, str]], path: Path) -> dict[str, np.ndarray]:
    rows = [line.split() for line in body.decode("ascii", errors="replace").splitlines() if line.strip()]
    if len(rows) != count:
        raise PlyError(f"header declares {count} vertices but {len(rows)} data lines follow", path)
    width = len(props)
    bad = next((i for i, row in enumerate(rows) if len(row) != width), None)
    if bad is not None:
        raise PlyError(f"vertex line {bad + 1} has {len(rows[bad])} values, expected {width}", path)
    try:
        table = np.array(rows, dtype=np.float64).reshape(count, width)
    except ValueError as exc:
        raise PlyError(f"non-numeric vertex value ({exc})", path) from exc
    return {name: _as_float32(table[:, i]) for i, (name, _) in enumerate(props)}


def _as_float32(values: np.ndarray) -> np.ndarray:
    """float32 copy; values beyond its range become ±inf quietly (refused by the finiteness check after)."""
    with np.errstate(over="ignore", invalid="ignore"):
        return values.astype(np.float32)
