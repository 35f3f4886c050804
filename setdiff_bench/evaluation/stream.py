"""Closed-loop enhancement: a SetDiff session that a simulator calls once per tick.

A :class:`StreamSession` holds one scene's recorded references (clean images + world cameras, with
their C-maps given or rendered from the scene's 3DGS PLY).  Each :meth:`StreamSession.enhance` call
takes one tick's rendered frames (RGB + world camera, C-maps given or rendered), picks the
session's ``max_references`` references by Eq. 2 (:func:`setdiff_bench.geometry.select_references`),
normalises references + frames into the first frame's camera (:func:`~setdiff_bench.geometry.normalize_packet`,
as ``prepare`` does), builds a :class:`~setdiff_bench.types.Packet` and enhances the tick's cameras
as one set with the loaded enhancer — the same code path as ``run --method setdiff``, so a tick whose
views match a prepared packet gives the same images (to the last 8-bit level).

Any frame size is accepted: the SetDiff / DiFix enhancers reflect-pad a packet to the size multiple their
network needs and crop the output back (:mod:`setdiff_bench.enhancers.padding`).

Shapes: images ``(V, 3, H, W)`` float32 in [0, 1]; C-maps ``(V, 3, H, W)`` world coordinates
(alpha-weighted, Eq. 1); alphas ``(V, 1, H, W)``.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.base import EstimatesMemory, KnowsTrainingData
from setdiff_bench.errors import OutOfDistributionWarning, UsageError
from setdiff_bench.evaluation.tick_limits import DEFAULT_REFERENCES_PER_TICK, MAX_CAMERAS_PER_TICK
from setdiff_bench.geometry import max_pairwise_distance, normalize_packet, select_references
from setdiff_bench.io.images import uint8_to_float
from setdiff_bench.runtime.memory import check_memory
from setdiff_bench.types import Packet, ViewSet

#: What a simulator can change when a tick does not fit in memory.
TICK_MEMORY_ADVICE = (
    "send fewer cameras per tick, start the session with fewer references (max_references), "
    "render smaller frames, or serve on another device"
)


class StreamInputError(UsageError):
    """A tick or a session's references are malformed (wrong size, NaN / non-rigid pose, too many cameras)."""


@dataclass
class Views:
    """Views given to a session: images, world cameras and (optionally) their C-maps and alphas.

    Attributes:
        images: ``(V, 3, H, W)`` uint8 (converted as an 8-bit PNG is read, so outputs match the batch
            runner's) or float32 in [0, 1].
        cameras: ``V`` world-frame cameras.
        cmaps: ``(V, 3, H, W)`` world-frame C-maps, or ``None`` to render them from the session's PLY.
        alphas: ``(V, 1, H, W)`` accumulated opacities (default ones where C-maps are given).
        names: ``V`` names (default ``view0``, ``view1``, ...).
    """

    images: torch.Tensor
    cameras: Sequence[Camera]
    cmaps: torch.Tensor | None = None
    alphas: torch.Tensor | None = None
    names: Sequence[str] | None = None


def _as_float(images: torch.Tensor) -> torch.Tensor:
    return uint8_to_float(images) if images.dtype == torch.uint8 else images.float()


def _check_views(views: Views, role: str, size: tuple[int, int] | None) -> tuple[int, int]:
    images = views.images
    if not isinstance(images, torch.Tensor) or images.ndim != 4 or images.shape[1] != 3:
        raise StreamInputError(
            f"images must be (V, 3, H, W), got {tuple(getattr(images, 'shape', ()))}", role
        )
    count, _, height, width = images.shape
    if count != len(views.cameras):
        raise StreamInputError(f"{count} images but {len(views.cameras)} cameras", role)
    if size is not None and (height, width) != size:
        raise StreamInputError(f"images are {width}x{height}, the session expects {size[1]}x{size[0]}", role)
    if images.is_floating_point() and not torch.isfinite(images).all():
        raise StreamInputError("images contain NaN or infinite values", role)
    for i, camera in enumerate(views.cameras):
        if (camera.height, camera.width) != (height, width):
            raise StreamInputError(
                f"camera {i} is {camera.width}x{camera.height}, image is {width}x{height}", role
            )
    for name, tensor, channels in (("C-maps", views.cmaps, 3), ("alphas", views.alphas, 1)):
        if tensor is not None and tuple(tensor.shape) != (count, channels, height, width):
            raise StreamInputError(
                f"{name} must be {(count, channels, height, width)}, got {tuple(tensor.shape)}", role
            )
        if tensor is not None and not torch.isfinite(tensor).all():
            raise StreamInputError(f"{name} contain NaN or infinite values", role)
    return int(height), int(width)


def _image_key(image: torch.Tensor) -> str:
    """Content key of one ``(3, H, W)`` model input (exact bytes, so only identical inputs share latents)."""
    data = image.detach().to("cpu", torch.float32).contiguous()
    return (
        f"{image.dtype}{tuple(data.shape)}"
        + hashlib.blake2b(data.numpy().tobytes(), digest_size=16).hexdigest()
    )


class ReferenceLatentCache:
    """Latents of a session's reference images, encoded once and reused on every tick.

    While :meth:`active` is entered, the model's ``encode`` looks each input view up by content: views
    seen before as references (never views whose decoder skips are requested — the targets) take
    their cached latents; the rest go through the model's own ``encode`` in one batch.  The VAE
    encoder treats views independently, so this changes the work done, not the model: results differ
    only by float rounding of a different batch size (at most one 8-bit level, measured in the tests).
    """

    def __init__(self) -> None:
        self.latents: dict[str, torch.Tensor] = {}
        self.hits = 0
        self.misses = 0

    @contextmanager
    def active(self, model: Any) -> Iterator[None]:
        encode = model.encode

        def cached_encode(images: torch.Tensor, keep_skips: torch.Tensor | None = None) -> Any:
            keep = set() if keep_skips is None else {int(i) for i in keep_skips.tolist()}
            keys = [_image_key(image) for image in images]
            cached = [i for i, key in enumerate(keys) if i not in keep and key in self.latents]
            if not cached or len(cached) == len(images):
                cached = []
                encoded = encode(images, keep_skips)
            else:
                fresh = [i for i in range(len(images)) if i not in set(cached)]
                position = {i: j for j, i in enumerate(fresh)}
                fresh_keep = (
                    None
                    if keep_skips is None
                    else torch.tensor(
                        [position[int(i)] for i in keep_skips.tolist()],
                        device=keep_skips.device,
                        dtype=keep_skips.dtype,
                    )
                )
                encoded_fresh = encode(images[fresh], fresh_keep)
                rows = [None] * len(images)
                for i in cached:
                    rows[i] = self.latents[keys[i]].to(images.device)
                for i in fresh:
                    rows[i] = encoded_fresh.latents[position[i]]
                encoded = replace(encoded_fresh, latents=torch.stack(rows))
            self.hits += len(cached)
            self.misses += len(images) - len(cached)
            for i, key in enumerate(keys):
                if i not in keep:  # references: targets are the views whose skips are kept
                    self.latents[key] = encoded.latents[i].detach()
            return encoded

        model.encode = cached_encode
        try:
            yield
        finally:
            del model.encode  # back to the class's method


class StreamSession:
    """One scene's enhancement session (references fixed, frames streamed tick by tick).

    Args:
        enhancer: a loaded SetDiff/DiFix enhancer (:func:`setdiff_bench.enhancers.setdiff.load_enhancer`).
        references: the recorded clean views of the scene (world frame).
        ply: the scene's 3DGS PLY, used to render C-maps wherever they are not given.
        max_references: references per tick (default: the enhancer's ``max_references`` option, or
            :data:`DEFAULT_REFERENCES_PER_TICK` where that is ``None``).
        max_cameras: most frames one tick may carry.
        cache_reference_latents: encode each reference once per session (:class:`ReferenceLatentCache`).
            Off by default: encoding a smaller batch changes float32 convolution rounding in the last
            bits, so with the cache an output pixel can differ from ``run --method setdiff`` by one 8-bit
            level; without it, outputs equal the batch runner's exactly.

    One session must not be used from two threads at once (the cache patches the model during a call).

    Raises:
        StreamInputError: malformed references, or C-maps missing with no PLY to render them.
    """

    def __init__(
        self,
        enhancer: Any,
        references: Views,
        *,
        ply: str | os.PathLike[str] | None = None,
        max_references: int | None = None,
        max_cameras: int = MAX_CAMERAS_PER_TICK,
        device: str = "cpu",
        cache_reference_latents: bool = False,
    ) -> None:
        self.enhancer = enhancer
        self.size = _check_views(references, "references", None)
        if len(references.cameras) == 0:
            raise StreamInputError("a session needs at least one recorded reference", "references")
        self._model = None
        self._device = device
        if ply is not None:
            # lazy: the CLI imports this module at startup (serve's settings); 3DGS loads only for a PLY
            from setdiff_bench.gaussians.ply import read_ply

            self._model = read_ply(Path(ply)).to(device)
        cmaps, alphas = self._geometry(references)
        self.references = ViewSet(
            names=tuple(references.names or (f"ref{i}" for i in range(len(references.cameras)))),
            images=_as_float(references.images),
            cmaps=cmaps,
            alphas=alphas,
            cameras=tuple(references.cameras),
        )
        if max_references is None:
            max_references = getattr(enhancer, "options", {}).get("max_references")
        if max_references is None:
            max_references = min(DEFAULT_REFERENCES_PER_TICK, len(self.references))
        self.max_references = int(max_references)
        self.max_cameras = max_cameras
        self.latent_cache = ReferenceLatentCache() if cache_reference_latents else None
        self.ticks = 0
        #: the one warning line when the references are unlike the enhancer's training data (else None)
        self.out_of_distribution = None
        if isinstance(enhancer, KnowsTrainingData):
            height, width = self.size
            self.out_of_distribution = enhancer.out_of_distribution([], [(height, width)], "this session")
            if self.out_of_distribution is not None:
                warnings.warn(self.out_of_distribution, OutOfDistributionWarning, stacklevel=2)

    def _geometry(self, views: Views) -> tuple[torch.Tensor, torch.Tensor]:
        count = len(views.cameras)
        height, width = views.images.shape[-2:]
        if views.cmaps is not None:
            alphas = views.alphas if views.alphas is not None else torch.ones(count, 1, height, width)
            return views.cmaps.float(), alphas.float()
        if self._model is None:
            raise StreamInputError("C-maps not given and the session has no PLY to render them", "cmaps")
        from setdiff_bench.gaussians.render import render

        with torch.no_grad():
            out = render(self._model, list(views.cameras), backend="torch")
        return out.cmap.float().cpu(), out.alpha.float().cpu()

    def select(self, cameras: Sequence[Camera]) -> list[int]:
        """Indices of the references used for a tick with these cameras (Eq. 2), in recorded order."""
        chosen = select_references(
            cameras,
            self.references.cameras,
            self.max_references,
            d_max=max_pairwise_distance(np.stack([c.center for c in (*cameras, *self.references.cameras)])),
        )
        return sorted(chosen)

    def packet(self, frames: Views) -> Packet:
        """The packet one tick is enhanced as (references chosen, everything normalised)."""
        if len(frames.cameras) > self.max_cameras:
            raise StreamInputError(
                f"{len(frames.cameras)} cameras in one tick; at most {self.max_cameras}", "frames"
            )
        if len(frames.cameras) == 0:
            raise StreamInputError("a tick needs at least one frame", "frames")
        _check_views(frames, "frames", self.size)
        refs = self.references.subset(self.select(frames.cameras))
        cmaps, alphas = self._geometry(frames)
        cameras = (*refs.cameras, *frames.cameras)
        normalised = normalize_packet(
            cameras, torch.cat([refs.cmaps, cmaps]), len(refs), alphas=torch.cat([refs.alphas, alphas])
        )
        n = len(refs)
        names = tuple(frames.names or (f"view{i}" for i in range(len(frames.cameras))))
        return Packet(
            packet_id=f"tick{self.ticks:06d}",
            dataset="stream",
            protocol="stream",
            group="stream",
            split="test",
            scene="stream",
            references=ViewSet(
                refs.names, refs.images, normalised.cmaps[:n], refs.alphas, normalised.cameras[:n]
            ),
            targets=ViewSet(
                names, _as_float(frames.images), normalised.cmaps[n:], alphas, normalised.cameras[n:]
            ),
            scale=normalised.scale,
        )

    def enhance(self, frames: Views) -> torch.Tensor:
        """Enhance one tick: ``(M, 3, H, W)`` float32 in [0, 1], in the order of ``frames``."""
        return self.enhance_packet(self.packet(frames))

    def enhance_packet(self, packet: Packet) -> torch.Tensor:
        """Enhance a packet built by :meth:`packet` (the model call alone, so servers can lock just it).

        Raises:
            MemoryNeedError: the enhancer estimates that this tick needs more memory than its device has
                available (nothing is enhanced; a tick with fewer cameras may fit).
        """
        if isinstance(self.enhancer, EstimatesMemory):
            needed = self.enhancer.memory_bytes(
                len(packet.references), len(packet.targets), packet.height, packet.width
            )
            what = (
                f"enhancing a tick of {len(packet.references)} references + {len(packet.targets)} frames of "
                f"{packet.width}x{packet.height} with {self.enhancer.name}"
            )
            check_memory(needed, self.enhancer.device, what, TICK_MEMORY_ADVICE, None)
        model = getattr(self.enhancer, "model", None)
        with torch.no_grad():
            if self.latent_cache is not None and hasattr(model, "encode"):
                with self.latent_cache.active(model):
                    out = self.enhancer.enhance(packet)
            else:
                out = self.enhancer.enhance(packet)
        self.ticks += 1
        return out.float().clamp(0.0, 1.0)
