"""Fuzzing the parsers of untrusted files with hypothesis: only ``SetDiffBenchError`` may escape.

Parsers and their inputs (each a valid file broken by :mod:`tests.reliability.mutations`):

* PLY (:func:`setdiff_bench.gaussians.ply.read_ply`): binary little/big-endian and ASCII files of SH
  degree 0 and 1, mutated as bytes or through their header lines;
* COLMAP text (:func:`setdiff_bench.loaders.colmap.read_colmap_model`, which reads through pycolmap):
  a pycolmap-written model (cameras, images with 2D points, points3D with tracks, rigs, frames) and a
  legacy two-file model, one or two files mutated as tokens/lines or bytes;
* ``transforms.json`` (:func:`setdiff_bench.loaders.nerfstudio.read_transforms`): with and without
  ``applied_transform`` and distortion, mutated as a JSON tree or as bytes;
* nuScenes tables (:func:`setdiff_bench.loaders.nuscenes.load_scenes`): one of the seven tables mutated as
  a JSON tree (dangling tokens, wrong types, broken chains, extreme numbers).

Any exception other than ``SetDiffBenchError`` fails, and so does a warning (a second stderr line in the
CLI), except deprecation warnings.  Error messages must be one line.  The default run draws
:data:`DEFAULT_EXAMPLES` inputs per parser (derandomised, so the same inputs every run); the slow suite
:data:`SLOW_EXAMPLES` per parser (random), and asserts the counts.
"""

from __future__ import annotations

import json
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pycolmap
import pytest
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.gaussians.ply import read_ply, write_ply
from setdiff_bench.loaders.colmap import read_colmap_model
from setdiff_bench.loaders.nerfstudio import read_transforms
from setdiff_bench.loaders.nuscenes import load_scenes as load_nuscenes
from tests.gaussians.gaussian_fixtures import ply_header, ply_property_names, random_model
from tests.loaders.loader_fixtures import (
    build_nuscenes,
    intrinsics,
    random_view,
    write_colmap_text_by_hand,
    write_image,
    write_transforms,
)
from tests.reliability.mutations import mutated_bytes, mutated_json, mutated_text

DEFAULT_EXAMPLES = 120
SLOW_EXAMPLES = 10_000


def fuzz(strategy: st.SearchStrategy[Any], check: Callable[[Any], None], examples: int, *, slow: bool) -> int:
    """Run ``check`` on ``examples`` inputs drawn from ``strategy``; returns how many it saw."""
    seen = 0

    @settings(
        max_examples=examples,
        deadline=None,
        database=None,
        derandomize=not slow,
        print_blob=True,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )
    @given(strategy)
    def run(value: Any) -> None:
        nonlocal seen
        seen += 1
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a warning would be a second line on the CLI's stderr
            warnings.simplefilter("ignore", DeprecationWarning)
            warnings.simplefilter("ignore", PendingDeprecationWarning)
            try:
                check(value)
            except SetDiffBenchError as error:
                assert "\n" not in str(error) and error.problem, repr(error)

    run()
    return seen


def fuzz_all(strategy: st.SearchStrategy[Any], check: Callable[[Any], None], *, slow: bool) -> None:
    """:func:`fuzz` with the run's number of examples (:data:`SLOW_EXAMPLES` when ``slow``, else
    :data:`DEFAULT_EXAMPLES`), asserting hypothesis generated that many."""
    examples = SLOW_EXAMPLES if slow else DEFAULT_EXAMPLES
    seen = fuzz(strategy, check, examples, slow=slow)
    assert seen >= examples, f"hypothesis generated {seen} inputs, fewer than {examples}"


# ---------------------------------------------------------------------- PLY
def ply_bases(folder: Path) -> list[bytes]:
    g = torch.Generator().manual_seed(3)
    write_ply(folder / "a.ply", random_model(4, 1, g))
    write_ply(folder / "b.ply", random_model(3, 0, g), normals=False)
    little = (folder / "b.ply").read_bytes()
    head, body = little.split(b"end_header\n", 1)
    big = (
        head.replace(b"binary_little_endian", b"binary_big_endian")
        + b"end_header\n"
        + np.frombuffer(body, "<f4").astype(">f4").tobytes()
    )
    names = [line.split()[-1] for line in head.decode().splitlines() if line.startswith("property")]
    rows = np.frombuffer(body, "<f4").reshape(-1, len(names))
    ascii_ = (
        head.replace(b"binary_little_endian", b"ascii")
        + b"end_header\n"
        + "".join(" ".join(f"{v:.6g}" for v in row) + "\n" for row in rows).encode()
    )
    return [(folder / "a.ply").read_bytes(), little, big, ascii_]


@st.composite
def ply_inputs(draw: st.DrawFn, bases: list[bytes]) -> bytes:
    base = draw(st.sampled_from(bases))
    if draw(st.booleans()):
        return draw(mutated_bytes(base))
    head, _, body = base.partition(b"end_header\n")
    return draw(mutated_text(head.decode("ascii"))).encode("utf-8") + b"end_header\n" + body


@pytest.fixture(scope="module")
def ply_case(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[bytes]]:
    folder = tmp_path_factory.mktemp("fuzz_ply")
    return folder / "fuzz.ply", ply_bases(folder)


def check_ply(path: Path) -> Callable[[bytes], None]:
    def check(raw: bytes) -> None:
        path.write_bytes(raw)
        read_ply(path)

    return check


# ---------------------------------------------------------------------- COLMAP text
def colmap_bases(folder: Path) -> list[dict[str, str]]:
    """Two models as {file name: text}: pycolmap-written (with tracks, rigs, frames) and legacy two-file."""
    rng = np.random.default_rng(12)
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(model="PINHOLE", width=32, height=24, params=[30, 28, 16, 12], camera_id=1)
    )
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(
            model="OPENCV",
            width=32,
            height=24,
            params=[30, 29, 15, 12, 0.01, -0.002, 0.001, 0.0005],
            camera_id=2,
        )
    )
    for image_id in (1, 2, 3):
        view = random_view(rng, intrinsics())
        image = pycolmap.Image(name=f"im_{image_id}.png", camera_id=1 + image_id % 2, image_id=image_id)
        image.points2D = pycolmap.Point2DList(
            [pycolmap.Point2D(np.array([3.0 + i, 4.0 + i])) for i in range(3)]
        )
        rec.add_image_with_trivial_frame(
            image, pycolmap.Rigid3d(pycolmap.Rotation3d(view.quat_xyzw()), view.t)
        )
    for index in range(2):
        track = pycolmap.Track()
        track.add_element(1, index)
        track.add_element(2, index)
        rec.add_point3D(rng.normal(size=3), track, np.array([10, 20, 30], np.uint8))
    full = folder / "full"
    full.mkdir()
    rec.write_text(str(full))
    legacy = write_colmap_text_by_hand(
        folder / "legacy", {f"im_{i}.png": random_view(rng, intrinsics()) for i in range(2)}
    )
    read_colmap_model(full), read_colmap_model(legacy)  # both bases are valid
    return [{p.name: p.read_text() for p in sorted(base.iterdir())} for base in (full, legacy)]


@st.composite
def colmap_inputs(draw: st.DrawFn, bases: list[dict[str, str]]) -> dict[str, bytes]:
    files = {name: text.encode() for name, text in draw(st.sampled_from(bases)).items()}
    for name in draw(st.lists(st.sampled_from(sorted(files)), min_size=1, max_size=2, unique=True)):
        if draw(st.integers(0, 3)) == 0:
            files[name] = draw(mutated_bytes(files[name]))
        else:
            files[name] = draw(mutated_text(files[name].decode())).encode("utf-8")
    return files


@pytest.fixture(scope="module")
def colmap_case(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[dict[str, str]]]:
    folder = tmp_path_factory.mktemp("fuzz_colmap")
    return folder / "sparse", colmap_bases(folder)


def check_colmap(folder: Path) -> Callable[[dict[str, bytes]], None]:
    def check(files: dict[str, bytes]) -> None:
        shutil.rmtree(folder, ignore_errors=True)
        folder.mkdir()
        for name, data in files.items():
            (folder / name).write_bytes(data)
        read_colmap_model(folder)

    return check


# ---------------------------------------------------------------------- transforms.json
@pytest.fixture(scope="module")
def transforms_case(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Any]]:
    folder = tmp_path_factory.mktemp("fuzz_transforms")
    rng = np.random.default_rng(8)
    views = {
        f"frame_{i:05d}.png": random_view(rng, intrinsics(), dist=np.array([0.01, -0.003, 0.001, 0.0]))
        for i in range(1, 4)
    }
    for name in views:
        write_image(folder / "images" / name)
    bases = []
    for applied in (True, False):
        path = write_transforms(folder, views, full_size=(32, 24), applied=applied)
        meta = json.loads(path.read_text())
        if not applied:
            meta.update({"k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "camera_model": "PINHOLE"})
            meta["frames"][1].update({"fl_x": 31.0, "w": 32, "h": 24})  # a per-frame override
        bases.append(meta)
        read_transforms(path)  # valid
    return folder / "transforms.json", bases


@st.composite
def transforms_inputs(draw: st.DrawFn, bases: list[Any]) -> bytes:
    tree = draw(mutated_json(draw(st.sampled_from(bases))))
    text = json.dumps(tree, indent=1).encode()  # NaN/Infinity as Python's json writes them
    return draw(mutated_bytes(text, max_ops=2)) if draw(st.integers(0, 3)) == 0 else text


def check_transforms(path: Path) -> Callable[[bytes], None]:
    def check(raw: bytes) -> None:
        path.write_bytes(raw)
        read_transforms(path, distortion="keep")

    return check


# ---------------------------------------------------------------------- nuScenes tables
@pytest.fixture(scope="module")
def nuscenes_case(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, list[dict]]]:
    fixture = build_nuscenes(
        tmp_path_factory.mktemp("fuzz_nuscenes"), np.random.default_rng(13), sweeps_between=1
    )
    root = fixture.write()
    load_nuscenes(root)  # valid
    return root, fixture.tables


@st.composite
def nuscenes_inputs(draw: st.DrawFn, tables: dict[str, list[dict]]) -> tuple[str, bytes]:
    name = draw(st.sampled_from(sorted(tables)))
    tree = draw(mutated_json(tables[name]))
    text = json.dumps(tree).encode()
    return name, (draw(mutated_bytes(text, max_ops=1)) if draw(st.integers(0, 7)) == 0 else text)


def check_nuscenes(root: Path, tables: dict[str, list[dict]]) -> Callable[[tuple[str, bytes]], None]:
    folder = root / "v1.0-mini"
    pristine = {name: json.dumps(records).encode() for name, records in tables.items()}

    def check(value: tuple[str, bytes]) -> None:
        name, raw = value
        (folder / f"{name}.json").write_bytes(raw)
        try:
            load_nuscenes(root)
        finally:
            (folder / f"{name}.json").write_bytes(pristine[name])

    return check


# ---------------------------------------------------------------------- the fuzz runs
@pytest.mark.parametrize(
    "case, fuzzed",
    [
        ("ply_case", lambda path, bases: (ply_inputs(bases), check_ply(path))),
        ("colmap_case", lambda folder, bases: (colmap_inputs(bases), check_colmap(folder))),
        ("transforms_case", lambda path, bases: (transforms_inputs(bases), check_transforms(path))),
        ("nuscenes_case", lambda root, tables: (nuscenes_inputs(tables), check_nuscenes(root, tables))),
    ],
    ids=["ply", "colmap_text", "transforms_json", "nuscenes_tables"],
)
@pytest.mark.parametrize(
    "slow", [pytest.param(False, id="default"), pytest.param(True, marks=pytest.mark.slow, id="10k")]
)
def test_fuzz(case: str, fuzzed, slow: bool, request: pytest.FixtureRequest) -> None:  # type: ignore[no-untyped-def]
    """A parser's inputs (its module fixture ``case`` → strategy and check): only ``SetDiffBenchError``
    escapes, with a one-line message."""
    strategy, check = fuzzed(*request.getfixturevalue(case))
    fuzz_all(strategy, check, slow=slow)


# ---------------------------------------------------------------------- regressions
PLY_HEADER = ply_header("ascii", 1, ply_property_names())


@pytest.mark.parametrize(
    "raw, problem",
    [
        (
            (PLY_HEADER + "1e252 0 0 0 0 0 0 0 0 0 1 0 0 0\n").encode(),
            "NaN or infinite means",
        ),  # float32 overflow
        (
            PLY_HEADER.replace(
                "property float rot_3\n", "property float rot_3\nproperty float f_rest_\x000\n"
            ).encode()
            + b"0 0 0 0 0 0 0 0 0 0 1 0 0 0 0\n",
            "malformed property name",
        ),
    ],
)
def test_ply_inputs_the_fuzzer_found(raw: bytes, problem: str, ply_case) -> None:
    path, _ = ply_case
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SetDiffBenchError, match=problem):
            check_ply(path)(raw)


@pytest.mark.parametrize(
    "edit, problem",
    [
        (lambda meta: meta.__setitem__("fl_x", 10**400), "intrinsic 'fl_x' must be a finite number"),
        (lambda meta: meta["applied_transform"][0].__setitem__(0, float("nan")), "applied_transform has NaN"),
        (
            lambda meta: [row.__setitem__(3, 1.7e308) for row in meta["frames"][0]["transform_matrix"][:3]],
            "overflowed",
        ),
    ],
)
def test_transforms_inputs_the_fuzzer_found(edit, problem: str, transforms_case) -> None:  # type: ignore[no-untyped-def]
    path, bases = transforms_case
    meta = json.loads(json.dumps(bases[0]))
    edit(meta)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SetDiffBenchError, match=problem):
            check_transforms(path)(json.dumps(meta).encode())
    meta = json.loads(json.dumps(bases[0]))
    meta["frames"][0]["colmap_im_id"] = float("nan")  # not an id: ignored, not a crash
    check_transforms(path)(json.dumps(meta).encode())


@pytest.mark.parametrize(
    "table, edit, problem",
    [
        ("calibrated_sensor", lambda r: r[0].__setitem__("token", ["x"]), "string 'token' field"),
        (
            "sample_data",
            lambda r: r[0].__setitem__("sample_token", [1]),
            "field 'sample_token' must be a JSON str",
        ),
        (
            "calibrated_sensor",
            lambda r: r[0].__setitem__("translation", [[1.0], 0.3, 1.6]),
            "translation must be numbers",
        ),
        ("sample_data", lambda r: r[0].__setitem__("width", [32]), "field 'width' must be a JSON int"),
    ],
)
def test_nuscenes_inputs_the_fuzzer_found(table: str, edit, problem: str, nuscenes_case) -> None:  # type: ignore[no-untyped-def]
    root, tables = nuscenes_case
    records = json.loads(json.dumps(tables[table]))
    edit(records)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(SetDiffBenchError, match=problem):
            check_nuscenes(root, tables)((table, json.dumps(records).encode()))
