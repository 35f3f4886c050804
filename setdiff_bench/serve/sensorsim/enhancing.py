"""Enhancing sensorsim frames: one :class:`~setdiff_bench.evaluation.stream.StreamSession` per scene and frame
size, holding that scene's recorded frames as references, bounded and expired as the enhancer server's
sessions are (:mod:`setdiff_bench.serve.sessions`).

A sensorsim request names no rollout: it carries the scene, the camera and its pose.  Everything the enhancer
keeps between ticks (the references, their C-maps, and with ``cache_reference_latents`` their latents) depends
on the scene and the frame size only, so concurrent rollouts of one scene share one session -- their ticks
take turns on it (its lock) and on the model (the FIFO lock), and each tick picks its own references by
Eq. 2 from the same recorded set: a rollout cannot see another's frames.  A session holds as many recorded
frames as fit in ``max_session_mib`` (28 bytes a pixel, plus the scene's PLY), evenly spaced over the
recording; a session unused for ``session_idle_timeout`` seconds expires and its memory is freed; at most
``max_sessions`` are open (the least recently used idle one is closed to open another).
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from setdiff_bench.evaluation.stream import StreamInputError, StreamSession, Views
from setdiff_bench.serve.rpc_errors import LOG
from setdiff_bench.serve.sensorsim.lens import LensCamera, render_lens
from setdiff_bench.serve.sensorsim.scenes import FittedScene
from setdiff_bench.serve.servicer import EnhancerService
from setdiff_bench.serve.sessions import FairLock, Session, release_freed_memory
from setdiff_bench.serve.settings import ServeSettings, reference_bytes


@dataclass(frozen=True)
class Frame:
    """One camera's frame of a tick: ``name`` (the camera), ``rgb`` ``(H, W, 3)`` uint8, its camera, and its
    C-map ``(3, H, W)`` / alpha ``(1, H, W)`` when already rendered (``None``: rendered from the PLY)."""

    name: str
    rgb: np.ndarray
    camera: LensCamera
    cmap: torch.Tensor | None = None
    alpha: torch.Tensor | None = None


class SceneSessions:
    """The open enhancement sessions, keyed by ``scene_id@HxW`` (the attributes ``sessions``,
    ``_sessions_lock`` and :meth:`expire_idle` are the enhancer server's, so its reaper serves both)."""

    def __init__(
        self, enhancer: Any, settings: ServeSettings, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.enhancer = enhancer
        self.settings = settings
        self.clock = clock
        self.sessions: collections.OrderedDict[str, Session] = collections.OrderedDict()
        self.expired: collections.OrderedDict[str, float] = collections.OrderedDict()
        self._sessions_lock = threading.Lock()
        self._opening = threading.Lock()
        self.model_lock = FairLock()
        self.opened = 0

    #: Close sessions idle past their timeout (none with a call in flight); returns how many -- the enhancer
    #: server's own method, over this table.
    expire_idle = EnhancerService.expire_idle

    def close_all(self) -> None:
        with self._sessions_lock:
            self.sessions.clear()
        release_freed_memory()

    def _acquire(self, scene: FittedScene, height: int, width: int) -> tuple[str, Session]:
        """The session of this scene and size, opened if needed, marked busy."""
        key = f"{scene.scene_id}@{height}x{width}"
        session = self._busy(key)
        if session is not None:
            return key, session
        with self._opening:  # one session opens at a time (rare); ticks of open sessions do not wait for it
            session = self._busy(key)
            if session is not None:
                return key, session
            session = self._open(scene, height, width)
            with self._sessions_lock:
                closed = self._make_room()
                self.sessions[key] = session
                session.busy += 1
                self.opened += 1
            if closed:
                release_freed_memory()
        LOG.info("enhancement session %s opened (%.1f MiB)", key, session.held_bytes / 2**20)
        return key, session

    def _busy(self, key: str) -> Session | None:
        """The open session ``key`` marked busy, or ``None``."""
        with self._sessions_lock:
            session = self.sessions.get(key)
            if session is not None:
                self.sessions.move_to_end(key)
                session.busy += 1
            return session

    def _make_room(self) -> int:
        """Close the least recently used idle sessions while ``max_sessions`` are open (lock held); how many."""
        closed = 0
        while len(self.sessions) >= self.settings.max_sessions:
            idle = [key for key, session in self.sessions.items() if session.busy == 0]
            if not idle:
                raise StreamInputError(
                    f"{len(self.sessions)} scene sessions are busy (at most {self.settings.max_sessions}); "
                    "retry, or serve with a larger --max-sessions",
                    "scene_id",
                )
            LOG.info("enhancement session %s closed to make room", idle[0])
            self.sessions.pop(idle[0])
            closed += 1
        return closed

    def _open(self, scene: FittedScene, height: int, width: int) -> Session:
        per_view = reference_bytes(height, width)
        budget = self.settings.max_session_bytes - scene.ply_bytes
        count = min(len(scene.recorded), budget // per_view if budget > 0 else 0)
        if count < 1:
            raise StreamInputError(
                f"one {width}x{height} reference ({per_view / 2**20:.1f} MiB) and the scene's PLY "
                f"({scene.ply_bytes / 2**20:.1f} MiB) exceed --max-session-mib {self.settings.max_session_mib:g}",
                "scene_id",
            )
        images, cameras, names = scene.recorded_views(height, width, int(count))
        geometry = render_lens(scene.gaussians, [LensCamera(c) for c in cameras], with_geometry=True)
        references = Views(
            images=torch.from_numpy(images).permute(0, 3, 1, 2).contiguous(),
            cameras=cameras,
            cmaps=geometry.cmap,
            alphas=geometry.alpha,
            names=names,
        )
        stream = StreamSession(
            self.enhancer,
            references,
            max_cameras=self.settings.max_cameras,
            cache_reference_latents=self.settings.cache_reference_latents,
        )
        return Session(
            stream,
            idle_timeout=self.settings.session_idle_timeout,
            held_bytes=len(cameras) * per_view + scene.ply_bytes,
            last_used=self.clock(),
        )

    def _release(self, session: Session) -> None:
        with self._sessions_lock:
            session.busy -= 1
            session.last_used = self.clock()

    def enhance(self, scene: FittedScene, frames: Sequence[Frame]) -> list[np.ndarray]:
        """Enhance one tick's frames of one scene and size as one set: ``(H, W, 3)`` uint8 each, in order.

        C-maps not given are rendered from the scene's PLY through each camera's lens.
        """
        height, width = frames[0].rgb.shape[:2]
        missing = [f for f in frames if f.cmap is None]
        if missing:
            drawn = render_lens(scene.gaussians, [f.camera for f in missing], with_geometry=True)
            rendered = {id(f): (drawn.cmap[i], drawn.alpha[i]) for i, f in enumerate(missing)}
        views = Views(
            images=torch.from_numpy(np.stack([f.rgb for f in frames])).permute(0, 3, 1, 2).contiguous(),
            cameras=[f.camera.camera for f in frames],
            cmaps=torch.stack([f.cmap if f.cmap is not None else rendered[id(f)][0] for f in frames]),
            alphas=torch.stack([f.alpha if f.alpha is not None else rendered[id(f)][1] for f in frames]),
            names=[f.name for f in frames],
        )
        key, session = self._acquire(scene, height, width)
        try:
            with session.lock:
                packet = session.stream.packet(views)
                with self.model_lock.hold(key):
                    images = session.stream.enhance_packet(packet)
        finally:
            self._release(session)
        quantised = torch.round(images.detach().float().clamp(0, 1) * 255).to(torch.uint8)
        return [np.ascontiguousarray(q.permute(1, 2, 0).numpy()) for q in quantised]
