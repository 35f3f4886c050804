"""A generic capture in instant-ngp's ``transforms.json`` form, for the tests of verbs that read one through the
``nerfstudio`` loader (``fit``, ``refit``)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

WIDTH, HEIGHT = 64, 48


def write_capture(folder: Path) -> None:
    """``folder/transforms.json`` in instant-ngp's form (global k1 k2 p1 p2, no camera_model); four
    frames on a circle looking at the origin, the third without an image."""
    (folder / "images").mkdir(parents=True)
    rng = np.random.default_rng(3)
    frames = []
    for i in range(4):
        angle = i * 0.3
        center = np.array([4 * np.sin(angle), 0.0, 4 * np.cos(angle)])
        back = center / np.linalg.norm(center)  # OpenGL camera z points away from the scene
        right = np.cross([0.0, 1.0, 0.0], back)
        right /= np.linalg.norm(right)
        up = np.cross(back, right)
        c2w = np.eye(4)
        c2w[:3, :3] = np.stack([right, up, back], axis=1)
        c2w[:3, 3] = center
        frames.append({"file_path": f"images/{i:04d}.png", "transform_matrix": c2w.tolist()})
        if i != 2:
            image = (rng.random((HEIGHT, WIDTH, 3)) * 255).astype(np.uint8)
            cv2.imwrite(str(folder / "images" / f"{i:04d}.png"), image)
    meta = {
        "fl_x": 60.0,
        "fl_y": 60.0,
        "cx": 32.0,
        "cy": 24.0,
        "w": float(WIDTH),
        "h": float(HEIGHT),
        "k1": 0.2,
        "k2": 0.05,
        "p1": 0.0,
        "p2": 0.0,
        "aabb_scale": 4,
        "frames": frames,
    }
    (folder / "transforms.json").write_text(json.dumps(meta))
