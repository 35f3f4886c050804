"""prepare with a distorted camera: the capture that enters a packet is resampled to the pinhole camera
the renderer draws (regression: it was either refused or, before that, drawn as pinhole silently)."""

from __future__ import annotations

import cv2
import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.intrinsics import Distortion
from setdiff_bench.packets.worker import _mask, capture_image
from setdiff_bench.packets.working_view import Crop, ViewJob

WIDTH, HEIGHT = 160, 120
K = np.array([[100.0, 0.0, 80.0], [0.0, 100.0, 60.0], [0.0, 0.0, 1.0]])
LENS = Distortion("OPENCV", (0.15, 0.02, 0.0, 0.0))


def _job(path, camera) -> ViewJob:
    return ViewJob(
        frame="f.png",
        sensor="cam",
        traversal="t",
        timestamp_us=None,
        image_path=path,
        mask_path=None,
        invert_mask=False,
        crop=Crop(0, 0, WIDTH, HEIGHT),
        camera=camera,
    )


def test_capture_of_a_distorted_camera_is_undistorted(tmp_path):
    # a white dot where the lens images the normalised point (0.6, 0.4): hand-computed OpenCV radial model
    xn, yn = 0.6, 0.4
    r2 = xn * xn + yn * yn
    radial = 1 + 0.15 * r2 + 0.02 * r2 * r2
    u_d, v_d = K[0, 0] * xn * radial + K[0, 2], K[1, 1] * yn * radial + K[1, 2]
    jj, ii = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)
    dot = np.exp(-((jj - u_d) ** 2 + (ii - v_d) ** 2) / 4.0)
    cv2.imwrite(str(tmp_path / "f.png"), np.rint(np.repeat(dot[..., None], 3, 2) * 255).astype(np.uint8))
    camera = Camera(K, np.eye(4), WIDTH, HEIGHT, LENS)
    image = capture_image(_job(tmp_path / "f.png", camera), (HEIGHT, WIDTH))
    weight = image[..., 0].astype(np.float64)
    u, v = (weight * jj).sum() / weight.sum(), (weight * ii).sum() / weight.sum()
    u_p, v_p = K[0, 0] * xn + K[0, 2], K[1, 1] * yn + K[1, 2]  # where the pinhole renderer puts the point
    assert np.hypot(u_d - u_p, v_d - v_p) > 5.0
    assert np.hypot(u - u_p, v - v_p) < 0.3
    keep = _mask(_job(tmp_path / "f.png", camera), (HEIGHT, WIDTH))
    assert keep[HEIGHT // 2, WIDTH // 2] and not keep.all()  # the corners the lens does not cover are out
