"""Camera constructors, conversions and validation against hand-built references."""

from __future__ import annotations

import numpy as np
import pycolmap
import pytest

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import CameraError
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at, matrix_to_quaternion, quaternion_to_matrix


def rotation_z(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def test_quaternion_orders_give_the_same_rotation_as_hand_formula() -> None:
    # 90 degrees about z: q = (cos 45°, 0, 0, sin 45°) in w, x, y, z.
    h = np.sqrt(0.5)
    expected = rotation_z(np.pi / 2)
    assert np.allclose(quaternion_to_matrix([h, 0, 0, h], order="wxyz"), expected, atol=1e-12)
    assert np.allclose(quaternion_to_matrix([0, 0, h, h], order="xyzw"), expected, atol=1e-12)
    # the same four numbers read in the wrong order are a different rotation
    assert not np.allclose(quaternion_to_matrix([h, 0, 0, h], order="xyzw"), expected)


def test_matrix_to_quaternion_round_trip_random() -> None:
    rng = np.random.default_rng(1)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = quaternion_to_matrix(q, order="wxyz")
        back = matrix_to_quaternion(R, order="wxyz")
        assert np.allclose(quaternion_to_matrix(back, order="wxyz"), R, atol=1e-12)
        assert np.allclose(matrix_to_quaternion(R, order="xyzw"), back[[1, 2, 3, 0]])


def test_quaternion_norm_check() -> None:
    with pytest.raises(CameraError, match="norm"):
        quaternion_to_matrix([1.002, 0, 0, 0], order="wxyz", source="poses.txt line 3")
    assert np.allclose(quaternion_to_matrix([1.0005, 0, 0, 0], order="wxyz"), np.eye(3))


def test_pycolmap_camera_matches_pycolmap_projection() -> None:
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(camera_id=1, model="PINHOLE", width=64, height=48, params=[55.0, 52.0, 31.0, 25.0])
    )
    q = np.array([0.1, -0.2, 0.3, 0.9])
    q /= np.linalg.norm(q)  # x, y, z, w for pycolmap
    pose = pycolmap.Rigid3d(pycolmap.Rotation3d(q), np.array([0.3, -0.2, 2.0]))
    rec.add_image_with_trivial_frame(pycolmap.Image(name="a.jpg", camera_id=1, image_id=1), pose)
    image = rec.images[1]
    camera = Camera.from_pycolmap(image, rec.cameras[1], source="test")
    points = np.array([[0.1, 0.2, 1.0], [-0.5, 0.3, 2.0], [0.2, -0.1, 0.5]])
    uv, depth = camera.project(points)
    cam_points = (pose.matrix()[:, :3] @ points.T).T + pose.matrix()[:, 3]
    expected = rec.cameras[1].img_from_cam(cam_points)
    assert np.allclose(uv, expected, atol=1e-9)
    assert np.allclose(depth, cam_points[:, 2])
    # unproject inverts project
    assert np.allclose(camera.unproject(uv, depth), points, atol=1e-9)


def test_opengl_c2w_conversion() -> None:
    # An OpenGL camera at (1, 2, 3) looking down world -z with y up: OpenCV forward must be -z.
    c2w_gl = np.eye(4)
    c2w_gl[:3, 3] = [1.0, 2.0, 3.0]
    camera = Camera.from_opengl_c2w(c2w_gl, intrinsics_matrix(10, 10, 5, 5), 10, 10)
    assert np.allclose(camera.center, [1, 2, 3])
    assert np.allclose(camera.view_direction, [0, 0, -1])
    # a point 2 m in front and 1 m above projects above the principal point (smaller v)
    uv, depth = camera.project(np.array([[1.0, 3.0, 1.0]]))
    assert depth[0] == pytest.approx(2.0)
    assert uv[0, 1] == pytest.approx(5 - 10 * 0.5)


def test_look_at_projects_target_to_principal_point() -> None:
    w2c = look_at([0, -10, 1.5], [3, 20, 1.0])
    camera = Camera(intrinsics_matrix(100, 100, 64, 48), w2c, 128, 96)
    uv, _ = camera.project(np.array([[3.0, 20.0, 1.0]]))
    assert np.allclose(uv, [[64, 48]], atol=1e-9)
    # world up projects upward in the image (OpenCV y down)
    uv_up, _ = camera.project(np.array([[3.0, 20.0, 2.0]]))
    assert uv_up[0, 1] < 48


@pytest.mark.parametrize(
    "bad, match",
    [
        (dict(w2c=np.diag([1.0, 1.0, -1.0, 1.0])), "determinant"),
        (dict(w2c=np.diag([1.0, 1.01, 1.0, 1.0])), "orthonormal"),
        (dict(K=intrinsics_matrix(-5, 5, 1, 1)), "focal"),
        (dict(w2c=np.full((4, 4), np.nan)), "NaN"),
    ],
)
def test_invalid_cameras_name_their_source(bad: dict, match: str) -> None:
    kwargs = dict(
        K=intrinsics_matrix(5, 5, 1, 1), w2c=np.eye(4), width=4, height=4, source="images.bin image 7"
    )
    kwargs.update(bad)
    with pytest.raises(CameraError, match=match) as info:
        Camera(**kwargs)
    assert "images.bin image 7" in str(info.value)


def test_resize_and_crop_keep_projection_consistent() -> None:
    camera = Camera(intrinsics_matrix(80, 70, 40.5, 30.5), look_at([0, 0, 0], [0, 5, 0.2]), 80, 60)
    point = np.array([[0.4, 5.0, 0.5]])
    uv, _ = camera.project(point)
    half = camera.resized(40, 30)
    uv_half, _ = half.project(point)
    assert np.allclose(uv_half, uv / 2)
    crop = camera.cropped(10, 5, 50, 40)
    uv_crop, _ = crop.project(point)
    assert np.allclose(uv_crop, uv - [10, 5])


def test_distortion_round_trip() -> None:
    from setdiff_bench.intrinsics import Distortion

    camera = Camera(
        intrinsics_matrix(100, 100, 50, 40),
        np.eye(4),
        100,
        80,
        distortion=Distortion("OPENCV", (0.05, -0.01, 0.001, -0.002)),
    )
    points = np.array([[0.1, 0.05, 1.0], [-0.3, 0.2, 1.5]])
    uv, depth = camera.project(points)
    # OpenCV's own distortion model as the reference
    import cv2

    ref, _ = cv2.projectPoints(
        points, np.zeros(3), np.zeros(3), camera.K, np.array([0.05, -0.01, 0.001, -0.002])
    )
    assert np.allclose(uv, ref[:, 0, :], atol=1e-9)
    assert np.allclose(camera.unproject(uv, depth), points, atol=1e-8)
