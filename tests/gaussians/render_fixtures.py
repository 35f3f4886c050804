"""Inputs of the ``render`` verb tests: a two-view COLMAP model (:func:`write_model`), it with a random
scene's PLY (:func:`write_inputs`) and the verb's arguments over them (:func:`render_args`)."""

from __future__ import annotations

from pathlib import Path

import pycolmap

from setdiff_bench.gaussians.ply import write_ply
from setdiff_bench.rotations import look_at, matrix_to_quaternion
from tests.gaussians.gaussian_fixtures import random_scene


def write_model(folder: Path, *, radial: float | None = None) -> None:
    rec = pycolmap.Reconstruction()
    camera = (
        pycolmap.Camera(camera_id=1, model="PINHOLE", width=40, height=30, params=[35.0, 35.0, 20.0, 15.0])
        if radial is None
        else pycolmap.Camera(
            camera_id=1, model="SIMPLE_RADIAL", width=40, height=30, params=[35.0, 20.0, 15.0, radial]
        )
    )
    rec.add_camera_with_trivial_rig(camera)
    for image_id, eye in enumerate([[0.0, 0.0, 0.0], [0.5, 0.2, 0.3]], start=1):
        w2c = look_at(eye, [0.0, 0.0, 6.0], up=(0.0, -1.0, 0.0))
        pose = pycolmap.Rigid3d(
            pycolmap.Rotation3d(matrix_to_quaternion(w2c[:3, :3], order="xyzw")), w2c[:3, 3]
        )
        rec.add_image_with_trivial_frame(
            pycolmap.Image(name=f"view_{image_id}.jpg", camera_id=1, image_id=image_id), pose
        )
    folder.mkdir(parents=True)
    rec.write_binary(str(folder))


def write_inputs(tmp_path: Path, gaussians: int, *, radial: float | None = None) -> None:
    """``tmp_path/sparse`` (:func:`write_model`) and ``tmp_path/scene.ply`` (a random scene of ``gaussians``)."""
    write_model(tmp_path / "sparse", radial=radial)
    write_ply(tmp_path / "scene.ply", random_scene(gaussians, seed=1))


def render_args(tmp_path: Path, *extra: str, ply: str = "scene.ply", out: str = "out") -> list[str]:
    """``render`` arguments: ``tmp_path/ply`` seen by the model ``tmp_path/sparse``, into ``tmp_path/out``."""
    return [
        "render",
        "--ply",
        str(tmp_path / ply),
        "--colmap",
        str(tmp_path / "sparse"),
        "--out",
        str(tmp_path / out),
        *extra,
    ]
