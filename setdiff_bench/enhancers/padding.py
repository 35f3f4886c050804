"""Pad a packet to the size multiple a network needs, and crop its output back (issue 41).

The SetDiff / DiFix networks map images to a latent grid ``latent_factor`` (8) times smaller, so both
image sides must be multiples of it.  Captures keep their native size (a ¼-size instant-ngp fox is
480×270), so an enhancer pads every view of the packet to the next multiple and crops its output back,
as image-to-image diffusion pipelines do:

- images, C-maps and alphas are **reflect**-padded (edge-replicated along an axis too short to reflect,
  i.e. a side of fewer pixels than the padding), the same pixels for every view;
- the padding is centred (``top = ⌊pad_h / 2⌋``, ``left = ⌊pad_w / 2⌋``, the rest at the bottom / right)
  and every camera becomes the camera of the padded image: width and height grow by the padding and the
  principal point moves by ``(left, top)``, so Plücker rays of the original pixels are unchanged and the
  padded border carries the rays of the pixels it extends;
- a packet already at a multiple is returned as the same object (the enhancer's output is then
  bit-identical to the unpadded code path).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from setdiff_bench.cameras import Camera
from setdiff_bench.types import Packet, ViewSet


@dataclass(frozen=True)
class Padding:
    """Pixels added on each side of an image (all ≥ 0)."""

    top: int = 0
    bottom: int = 0
    left: int = 0
    right: int = 0

    @property
    def is_zero(self) -> bool:
        """Whether nothing is added."""
        return not (self.top or self.bottom or self.left or self.right)


def padding_for(height: int, width: int, multiple: int) -> Padding:
    """The centred padding that takes an ``height × width`` image to the next multiple of ``multiple``.

    Raises:
        ValueError: a non-positive size or multiple.
    """
    if height < 1 or width < 1 or multiple < 1:
        raise ValueError(f"size {height}x{width} and multiple {multiple} must be positive")
    pad_h = -height % multiple
    pad_w = -width % multiple
    return Padding(top=pad_h // 2, bottom=pad_h - pad_h // 2, left=pad_w // 2, right=pad_w - pad_w // 2)


def padded_size(height: int, width: int, multiple: int) -> tuple[int, int]:
    """``(H', W')``: both sides rounded up to a multiple of ``multiple``."""
    padding = padding_for(height, width, multiple)
    return height + padding.top + padding.bottom, width + padding.left + padding.right


def pad_images(images: torch.Tensor, padding: Padding) -> torch.Tensor:
    """``(V, C, H, W)`` → ``(V, C, H + top + bottom, W + left + right)``, reflect-padded.

    An axis whose padding on one side is not smaller than its length cannot be reflected
    (``torch.nn.functional.pad``'s rule); that axis is edge-replicated instead.
    """
    if padding.is_zero:
        return images
    height, width = int(images.shape[-2]), int(images.shape[-1])
    out = images
    for pads, length in (
        ((padding.left, padding.right, 0, 0), width),
        ((0, 0, padding.top, padding.bottom), height),
    ):
        if not any(pads):
            continue
        mode = "reflect" if max(pads) < length else "replicate"
        out = F.pad(out, pads, mode=mode)
    return out


def pad_camera(camera: Camera, padding: Padding) -> Camera:
    """The camera of the padded image: principal point moved by ``(left, top)``, size grown by the padding."""
    if padding.is_zero:
        return camera
    K = np.array(camera.K, dtype=np.float64)
    K[0, 2] += padding.left
    K[1, 2] += padding.top
    return Camera(
        K,
        camera.w2c,
        camera.width + padding.left + padding.right,
        camera.height + padding.top + padding.bottom,
        camera.distortion,
        camera.source,
    )


def pad_view_set(views: ViewSet, padding: Padding) -> ViewSet:
    """Images, C-maps and alphas reflect-padded alike, cameras moved to the padded image (names and
    timestamps kept)."""
    if padding.is_zero:
        return views
    return dataclasses.replace(
        views,
        images=pad_images(views.images, padding),
        cmaps=pad_images(views.cmaps, padding),
        alphas=pad_images(views.alphas, padding),
        cameras=tuple(pad_camera(camera, padding) for camera in views.cameras),
    )


def pad_packet(packet: Packet, multiple: int) -> tuple[Packet, Padding]:
    """``packet`` with every view padded to a multiple of ``multiple``, and the padding used.

    A packet whose size is already a multiple is returned unchanged (the same object).
    """
    padding = padding_for(packet.height, packet.width, multiple)
    if padding.is_zero:
        return packet, padding
    padded = dataclasses.replace(
        packet,
        references=pad_view_set(packet.references, padding),
        targets=pad_view_set(packet.targets, padding),
    )
    return padded, padding


def crop(images: torch.Tensor, padding: Padding) -> torch.Tensor:
    """``(V, C, H', W')`` → ``(V, C, H' − top − bottom, W' − left − right)``: the padding removed."""
    if padding.is_zero:
        return images
    height, width = int(images.shape[-2]), int(images.shape[-1])
    return images[
        ..., padding.top : height - padding.bottom, padding.left : width - padding.right
    ].contiguous()
