"""Sensorsim cameras → the project's cameras, and rendering through their lenses.

A render request names its camera by a ``CameraSpec`` (OpenCV pinhole with rational, tangential and thin-prism
distortion, OpenCV fisheye, or f-theta), the intrinsics' own resolution, the resolution wanted, and the camera's
pose at the start and the end of the exposure (``PosePair``, camera to world).  Conventions at this boundary:

* **axes**: sensorsim camera frames are taken as OpenCV's (x right, y down, z forward), the project's;
* **pose**: the exposure's middle (translations averaged, rotations interpolated linearly and renormalised;
  the start pose itself when the end pose equals it or is absent); the shutter type is not modelled;
* **principal point**: OpenCV's (integer = pixel centre); the project's ``K`` puts pixel centres at +0.5;
* **resolution**: intrinsics are scaled per axis from ``CameraSpec.resolution_h/w`` to the request's size.

Rendering (:func:`render_lens`): the rasteriser draws pinhole images only, so a distorted lens is drawn as a
pinhole *canvas* that covers the lens's rays, then resampled to the lens (``cv2.remap``, bilinear) -- RGB,
C-map and alpha alike.  Rays more than :data:`MAX_RAY_ANGLE_DEG` from the optical axis cannot be drawn on a
pinhole canvas: they are black with alpha 0.  The canvas is at most :data:`CANVAS_SCALE` times the output
per side (its focal length is lowered when the lens is wider).  An undistorted pinhole renders directly.

Shapes: images ``(V, 3, H, W)``, C-maps ``(V, 3, H, W)``, alphas ``(V, 1, H, W)``, float32.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import CameraError
from setdiff_bench.evaluation.stream import StreamInputError
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import matrix_to_quaternion, quaternion_to_matrix
from setdiff_bench.serve.sensorsim import common_pb2 as common
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb

#: Rays farther than this from the optical axis are not drawn (a pinhole canvas cannot hold them).
MAX_RAY_ANGLE_DEG = 80.0
#: The pinhole canvas a distorted lens is drawn on is at most this many times the output, per side.
CANVAS_SCALE = 2.0
#: Largest output side served (pixels): AlpaSim's presets go up to 2168 × 3848.
MAX_SIDE = 4096
#: Iterations of the fixed-point / Newton inversions of the lens models.
INVERSION_STEPS = 20


@dataclass(frozen=True)
class Lens:
    """A lens model: ``"pinhole"`` (no distortion), ``"opencv_pinhole"`` or ``"opencv_fisheye"``.

    ``coefficients``: OpenCV pinhole ``k1..k6, p1, p2, s1..s4`` (12) or fisheye ``k1..k4`` (4);
    ``max_angle``: the fisheye's largest ray angle (radians; 0 = unbounded).
    """

    model: str = "pinhole"
    coefficients: tuple[float, ...] = ()
    max_angle: float = 0.0

    @property
    def distorted(self) -> bool:
        return self.model == "opencv_fisheye" or any(c != 0.0 for c in self.coefficients)


@dataclass(frozen=True)
class LensCamera:
    """A requested camera: ``camera`` holds the pose, size and focal lengths / principal point as a pinhole
    ``K`` (what reference selection and the enhancer's rays see), ``lens`` how its pixels map to rays."""

    camera: Camera
    lens: Lens = Lens()


# ---------------------------------------------------------------------------------------------- poses
def pose_matrix(pose: common.Pose, what: str) -> np.ndarray:
    """``(4, 4)`` rigid transform of a pose message (``R(quat) p + vec``)."""
    q = pose.quat
    try:
        rotation = quaternion_to_matrix([q.w, q.x, q.y, q.z], order="wxyz", source=what)
    except CameraError as error:
        raise StreamInputError(error.problem, what) from None
    translation = np.array([pose.vec.x, pose.vec.y, pose.vec.z], dtype=np.float64)
    if not np.isfinite(translation).all():
        raise StreamInputError("translation has NaN or infinite values", what)
    matrix = np.eye(4)
    matrix[:3, :3] = rotation
    matrix[:3, 3] = translation
    return matrix


def pose_message(matrix: np.ndarray) -> common.Pose:
    """A ``(4, 4)`` rigid transform as a pose message."""
    w, x, y, z = matrix_to_quaternion(matrix[:3, :3], order="wxyz")
    tx, ty, tz = (float(v) for v in matrix[:3, 3])
    return common.Pose(vec=common.Vec3(x=tx, y=ty, z=tz), quat=common.Quat(w=w, x=x, y=y, z=z))


def exposure_pose(pair: pb.PosePair, what: str) -> np.ndarray:
    """Camera-to-world ``(4, 4)`` at the middle of the exposure (end pose absent: the start pose)."""
    if not pair.HasField("start_pose"):
        raise StreamInputError("sensor_pose has no start_pose", what)
    start = pose_matrix(pair.start_pose, f"{what} sensor_pose.start_pose")
    if not pair.HasField("end_pose") or pair.end_pose == pair.start_pose:
        return start
    end = pose_matrix(pair.end_pose, f"{what} sensor_pose.end_pose")
    q0 = matrix_to_quaternion(start[:3, :3], order="wxyz")
    q1 = matrix_to_quaternion(end[:3, :3], order="wxyz")
    middle = q0 + (q1 if float(q0 @ q1) >= 0 else -q1)
    mid = np.eye(4)
    mid[:3, :3] = quaternion_to_matrix(middle / np.linalg.norm(middle), order="wxyz")
    mid[:3, 3] = 0.5 * (start[:3, 3] + end[:3, 3])
    return mid


# ---------------------------------------------------------------------------------------------- cameras
def lens_camera(request: pb.RGBRenderRequest, what: str) -> LensCamera:
    """The camera of a render request, validated (one :class:`StreamInputError` line naming the field).

    Raises:
        StreamInputError: zero or too large a resolution, f-theta or windshield distortion (not served),
            no camera model, non-positive focal lengths, a bad pose.
    """
    height, width = int(request.resolution_h), int(request.resolution_w)
    if not (0 < height <= MAX_SIDE and 0 < width <= MAX_SIDE):
        raise StreamInputError(
            f"resolution_h x resolution_w must be 1..{MAX_SIDE} each, got {height}x{width}", what
        )
    spec = request.camera_intrinsics
    kind = spec.WhichOneof("camera_param")
    if kind == "ftheta_param":
        raise StreamInputError(
            "f-theta cameras are not served (OpenCV pinhole and OpenCV fisheye are); "
            "give this camera as opencv_pinhole_param or opencv_fisheye_param",
            what,
        )
    if kind is None:
        raise StreamInputError("camera_intrinsics has no camera model (opencv_pinhole_param expected)", what)
    if spec.WhichOneof("external_distortion") is not None:
        raise StreamInputError("windshield distortion (external_distortion) is not served", what)
    params = getattr(spec, kind)
    scale_x = width / spec.resolution_w if spec.resolution_w else 1.0
    scale_y = height / spec.resolution_h if spec.resolution_h else 1.0
    fx, fy = params.focal_length_x * scale_x, params.focal_length_y * scale_y
    cx = (params.principal_point_x + 0.5) * scale_x
    cy = (params.principal_point_y + 0.5) * scale_y
    if not all(math.isfinite(v) for v in (fx, fy, cx, cy)) or fx <= 0 or fy <= 0:
        raise StreamInputError(f"focal lengths must be positive and finite, got fx={fx:g} fy={fy:g}", what)
    if kind == "opencv_pinhole_param":
        coefficients = (
            _padded(params.radial_coeffs, 6, "radial_coeffs", what)
            + _padded(params.tangential_coeffs, 2, "tangential_coeffs", what)
            + _padded(params.thin_prism_coeffs, 4, "thin_prism_coeffs", what)
        )
        lens = Lens("opencv_pinhole", coefficients) if any(coefficients) else Lens()
    else:
        max_angle = float(params.max_angle)
        if not math.isfinite(max_angle) or max_angle < 0:
            raise StreamInputError(f"max_angle must be >= 0 radians, got {max_angle:g}", what)
        lens = Lens("opencv_fisheye", _padded(params.radial_coeffs, 4, "radial_coeffs", what), max_angle)
    c2w = exposure_pose(request.sensor_pose, what)
    try:
        camera = Camera.from_c2w(c2w, intrinsics_matrix(fx, fy, cx, cy), width, height, source=what)
    except CameraError as error:
        raise StreamInputError(error.problem, what) from None
    return LensCamera(camera, lens)


def _padded(values: Sequence[float], count: int, name: str, what: str) -> tuple[float, ...]:
    if len(values) > count:
        raise StreamInputError(f"{name} has {len(values)} values; at most {count}", what)
    padded = tuple(float(v) for v in values) + (0.0,) * (count - len(values))
    if not all(math.isfinite(v) for v in padded):
        raise StreamInputError(f"{name} has NaN or infinite values", what)
    return padded


def camera_spec(camera: Camera, logical_id: str) -> pb.CameraSpec:
    """A recorded pinhole camera as a ``CameraSpec`` (OpenCV principal point, global shutter)."""
    return pb.CameraSpec(
        opencv_pinhole_param=pb.OpenCVPinholeCameraParam(
            principal_point_x=camera.cx - 0.5,
            principal_point_y=camera.cy - 0.5,
            focal_length_x=camera.fx,
            focal_length_y=camera.fy,
            radial_coeffs=[0.0] * 6,
            tangential_coeffs=[0.0] * 2,
            thin_prism_coeffs=[0.0] * 4,
        ),
        logical_id=logical_id,
        resolution_h=camera.height,
        resolution_w=camera.width,
        shutter_type=pb.ShutterType.GLOBAL,
    )


# ---------------------------------------------------------------------------------------------- lens models
def _distort_pinhole(k: tuple[float, ...], x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's rational + tangential + thin-prism model on normalised coordinates."""
    k1, k2, k3, k4, k5, k6, p1, p2, s1, s2, s3, s4 = k
    r2 = x * x + y * y
    r4 = r2 * r2
    radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r4
    return xd, yd


def _pinhole_rays(k: tuple[float, ...], xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, ...]:
    """Undistorted ``(x, y)`` of distorted normalised coordinates (fixed point, as ``cv::undistortPoints``)
    and where the inversion converged (re-distorting lands within 1e-4 of the input)."""
    k1, k2, k3, k4, k5, k6, p1, p2, s1, s2, s3, s4 = k
    x, y = xd.copy(), yd.copy()
    with np.errstate(all="ignore"):
        for _ in range(INVERSION_STEPS):
            r2 = x * x + y * y
            r4 = r2 * r2
            radial = (1 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
            dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x) + s1 * r2 + s2 * r4
            dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y + s3 * r2 + s4 * r4
            x, y = (xd - dx) / radial, (yd - dy) / radial
        rx, ry = _distort_pinhole(k, x, y)
        valid = np.isfinite(x) & np.isfinite(y) & (np.hypot(rx - xd, ry - yd) < 1e-4)
    return x, y, valid


def _fisheye_rays(lens: Lens, xd: np.ndarray, yd: np.ndarray) -> tuple[np.ndarray, ...]:
    """Pinhole ``(x, y) = tan(θ) (cos φ, sin φ)`` of fisheye coordinates ``θ_d (cos φ, sin φ)``, where
    ``θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`` (Newton), and which rays are drawable."""
    k1, k2, k3, k4 = lens.coefficients
    theta_d = np.hypot(xd, yd)
    theta = theta_d.copy()
    with np.errstate(all="ignore"):
        for _ in range(INVERSION_STEPS):
            t2 = theta * theta
            value = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d
            slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
            theta = theta - value / slope
        t2 = theta * theta
        residual = np.abs(theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - theta_d)
        slope = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
        limit = math.radians(MAX_RAY_ANGLE_DEG)
        if lens.max_angle > 0:
            limit = min(limit, lens.max_angle)
        valid = np.isfinite(theta) & (theta >= 0) & (theta <= limit) & (residual < 1e-6) & (slope > 0)
        scale = np.where(theta_d > 0, np.tan(np.where(valid, theta, 0.0)) / np.maximum(theta_d, 1e-300), 1.0)
    return xd * scale, yd * scale, valid


@dataclass(frozen=True)
class _Resampling:
    """A pinhole canvas ``K`` and size, and the ``remap`` maps from the lens's pixels into it."""

    K: np.ndarray
    width: int
    height: int
    map_x: np.ndarray
    map_y: np.ndarray
    valid: np.ndarray


@functools.lru_cache(maxsize=64)
def _resampling(lens: Lens, K_values: tuple[float, ...], width: int, height: int) -> _Resampling:
    """The canvas and maps of one lens at one size (cached: a rollout asks the same cameras every tick)."""
    K = np.array(K_values).reshape(3, 3)
    jj, ii = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    xd = (jj - K[0, 2]) / K[0, 0]
    yd = (ii - K[1, 2]) / K[1, 1]
    if lens.model == "opencv_fisheye":
        x, y, valid = _fisheye_rays(lens, xd, yd)
    else:
        x, y, valid = _pinhole_rays(lens.coefficients, xd, yd)
        bound = math.tan(math.radians(MAX_RAY_ANGLE_DEG))
        valid &= (np.abs(x) <= bound) & (np.abs(y) <= bound)
    if not valid.any():
        raise StreamInputError("no pixel of this lens maps to a drawable ray", "camera_intrinsics")
    x_lo, x_hi = float(x[valid].min()), float(x[valid].max())
    y_lo, y_hi = float(y[valid].min()), float(y[valid].max())
    focal = min(K[0, 0], K[1, 1])
    focal = min(
        focal,
        CANVAS_SCALE * width / max(x_hi - x_lo, 1e-9),
        CANVAS_SCALE * height / max(y_hi - y_lo, 1e-9),
    )
    canvas_w = max(1, math.ceil(focal * (x_hi - x_lo)) + 2)
    canvas_h = max(1, math.ceil(focal * (y_hi - y_lo)) + 2)
    cx, cy = 1.0 - focal * x_lo, 1.0 - focal * y_lo
    map_x = np.where(valid, focal * x + cx - 0.5, -1.0).astype(np.float32)
    map_y = np.where(valid, focal * y + cy - 0.5, -1.0).astype(np.float32)
    return _Resampling(intrinsics_matrix(focal, focal, cx, cy), canvas_w, canvas_h, map_x, map_y, valid)


def _remap(images: torch.Tensor, plan: _Resampling) -> torch.Tensor:
    """``(V, C, h, w)`` canvas images → ``(V, C, H, W)`` through the lens (bilinear; outside: 0)."""
    out = []
    for image in images.detach().to("cpu", torch.float32).numpy():
        channels = [
            cv2.remap(
                np.ascontiguousarray(channel),
                plan.map_x,
                plan.map_y,
                interpolation=cv2.INTER_LINEAR,
                borderMode=cv2.BORDER_CONSTANT,
                borderValue=0,
            )
            for channel in image
        ]
        stacked = np.stack(channels) * plan.valid[None]
        out.append(torch.from_numpy(stacked.astype(np.float32)))
    return torch.stack(out)


@dataclass(frozen=True)
class LensRender:
    """What :func:`render_lens` draws: ``rgb`` ``(V, 3, H, W)`` in [0, 1], ``cmap`` ``(V, 3, H, W)`` (Eq. 1,
    world frame) and ``alpha`` ``(V, 1, H, W)``; ``cmap``/``alpha`` are ``None`` without geometry."""

    rgb: torch.Tensor
    cmap: torch.Tensor | None
    alpha: torch.Tensor | None


def render_lens(gaussians: object, cameras: Sequence[LensCamera], *, with_geometry: bool) -> LensRender:
    """Render ``cameras`` (same size) through their lenses from a :class:`~setdiff_bench.gaussians.model.GaussianModel`."""
    from setdiff_bench.gaussians.render import render  # lazy: the CLI reads this module's settings only

    rgbs, cmaps, alphas = [], [], []
    with torch.no_grad():
        for item in cameras:
            camera = item.camera
            if not item.lens.distorted:
                out = render(gaussians, [camera], with_geometry=with_geometry)
                rgb, cmap, alpha = out.rgb.float().cpu(), out.cmap, out.alpha.float().cpu()
                cmap = None if cmap is None else cmap.float().cpu()
            else:
                plan = _resampling(
                    item.lens, tuple(camera.K.reshape(-1).tolist()), camera.width, camera.height
                )
                canvas = Camera(plan.K, camera.w2c, plan.width, plan.height, source=camera.source)
                out = render(gaussians, [canvas], with_geometry=with_geometry)
                rgb, alpha = _remap(out.rgb, plan), _remap(out.alpha, plan)
                cmap = None if out.cmap is None else _remap(out.cmap, plan)
            rgbs.append(rgb.clamp(0.0, 1.0))
            alphas.append(alpha)
            cmaps.append(cmap)
    return LensRender(
        rgb=torch.cat(rgbs),
        cmap=torch.cat(cmaps) if with_geometry else None,
        alpha=torch.cat(alphas) if with_geometry else None,
    )
