"""The enhancer server's RPC handlers (:class:`EnhancerService`, ``enhancer.proto``): the session table
(start, use, expire, close), request checks (session ids, PLY names under ``--ply-root``, reference
memory, camera count) and the model calls, serialised by a FIFO lock."""

from __future__ import annotations

import collections
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import grpc

from setdiff_bench.evaluation.stream import StreamInputError, StreamSession
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve import enhancer_pb2_grpc as pb_grpc
from setdiff_bench.serve.rpc_errors import LOG, Refusal, rpc
from setdiff_bench.serve.sessions import (
    EXPIRED_MEMORY,
    FairLock,
    Session,
    release_freed_memory,
    session_bytes,
)
from setdiff_bench.serve.settings import ServeSettings
from setdiff_bench.serve.wire import from_views, images_to_arrays
from setdiff_bench.version import __version__

#: Longest session id or PLY name a request may carry (characters; ours are 36-character UUIDs).
MAX_ID_CHARS = 64


class EnhancerService(pb_grpc.EnhancerServicer):
    """The RPC handlers; ``enhancer`` is a loaded SetDiff/DiFix enhancer."""

    def __init__(
        self, enhancer: Any, settings: ServeSettings, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.enhancer = enhancer
        self.settings = settings
        self.clock = clock  # seconds, monotonic (idle expiry)
        self.sessions: dict[str, Session] = {}
        self.expired: collections.OrderedDict[str, float] = collections.OrderedDict()
        self.internal_errors = 0
        self._sessions_lock = threading.Lock()
        self.model_lock = FairLock()

    # ------------------------------------------------------------------ sessions
    def expire_idle(self, now: float | None = None) -> int:
        """Drop sessions idle past their timeout (none with a call in flight); returns how many."""
        now = self.clock() if now is None else now
        with self._sessions_lock:
            stale = [
                key
                for key, session in self.sessions.items()
                if session.busy == 0 and now - session.last_used > session.idle_timeout
            ]
            for key in stale:
                self.expired[key] = self.sessions.pop(key).idle_timeout
                while len(self.expired) > EXPIRED_MEMORY:
                    self.expired.popitem(last=False)
        for key in stale:
            LOG.info("session %s expired", key)
        if stale:
            release_freed_memory()
        return len(stale)

    @staticmethod
    def _check_id(session_uuid: str) -> None:
        """Refuse what cannot be a session id (ids are echoed in answers: keep them short and printable)."""
        if not 0 < len(session_uuid) <= MAX_ID_CHARS or not session_uuid.isprintable():
            raise StreamInputError(
                f"not a session id ({len(session_uuid)} characters; ids are at most {MAX_ID_CHARS} printable)",
                "session_uuid",
            )

    def _missing(self, session_uuid: str) -> Refusal:
        timeout = self.expired.get(session_uuid)
        if timeout is not None:
            return Refusal(
                grpc.StatusCode.NOT_FOUND,
                f"session {session_uuid!r} expired after {timeout:g} s without a call; start a new session",
            )
        return Refusal(grpc.StatusCode.NOT_FOUND, f"unknown session {session_uuid!r}")

    @contextmanager
    def _using(self, session_uuid: str) -> Iterator[Session]:
        """The session, marked busy (it cannot expire) for the duration of the call."""
        self._check_id(session_uuid)
        with self._sessions_lock:
            session = self.sessions.get(session_uuid)
            idle = session is not None and session.busy == 0
            if idle and self.clock() - session.last_used > session.idle_timeout:  # the reaper is late
                self.expired[session_uuid] = self.sessions.pop(session_uuid).idle_timeout
                session = None
            if session is None:
                raise self._missing(session_uuid)
            session.busy += 1
        try:
            yield session
        finally:
            with self._sessions_lock:
                session.busy -= 1
                session.last_used = self.clock()

    # ------------------------------------------------------------------ RPCs
    @rpc
    def start_session(self, request: pb.StartSessionRequest, context: grpc.ServicerContext) -> pb.SessionId:
        settings = self.settings
        if request.max_references < 0:
            raise StreamInputError(f"max_references must be >= 0, got {request.max_references}", "")
        lease = request.idle_timeout_s
        if lease != lease or lease < 0 or lease > settings.session_idle_timeout:  # NaN too
            raise StreamInputError(
                f"idle_timeout_s must be 0 (the server's) or up to {settings.session_idle_timeout:g} s, got {lease:g}",
                "",
            )
        held = session_bytes(request)
        ply = self._ply(request.ply_path) if request.ply_path else None
        if ply is not None:
            held += ply.stat().st_size
        if held > settings.max_session_bytes:
            raise Refusal(
                grpc.StatusCode.RESOURCE_EXHAUSTED,
                f"the session would hold {held / 2**20:.1f} MiB of references "
                f"({len(request.references)} views); at most {settings.max_session_mib:g} MiB per session",
            )
        self.expire_idle()
        with self._sessions_lock:  # refuse before decoding when no slot is free
            if len(self.sessions) >= settings.max_sessions:
                raise self._full()
        references = from_views(request.references, "references")
        stream = StreamSession(
            self.enhancer,
            references,
            ply=ply,
            max_references=request.max_references or None,
            max_cameras=settings.max_cameras,
            cache_reference_latents=settings.cache_reference_latents,
        )
        session = Session(
            stream,
            idle_timeout=lease or settings.session_idle_timeout,
            held_bytes=held,
            last_used=self.clock(),
        )
        with self._sessions_lock:
            if len(self.sessions) >= settings.max_sessions:
                raise self._full()
            session_uuid = str(uuid.uuid4())
            self.sessions[session_uuid] = session
        return pb.SessionId(session_uuid=session_uuid, idle_timeout_s=session.idle_timeout)

    def _ply(self, name: str) -> Path:
        """``name`` as a ``.ply`` file under ``settings.ply_root`` (no absolute paths, no way out of it)."""
        root = self.settings.ply_root
        if root is None:
            raise StreamInputError(
                "this server reads no PLY files (it was started without --ply-root)", "ply_path"
            )
        if len(name) > 4 * MAX_ID_CHARS or not name.isprintable():
            raise StreamInputError(
                f"a PLY name of {len(name)} characters, or with control characters", "ply_path"
            )
        relative = Path(name)
        resolved_root = root.resolve()
        candidate = (resolved_root / relative).resolve()
        if (
            relative.is_absolute()
            or not candidate.is_relative_to(resolved_root)
            or candidate.suffix != ".ply"
        ):
            raise StreamInputError(
                f"{name!r} must be a .ply file relative to the server's --ply-root", "ply_path"
            )
        if not candidate.is_file():
            raise StreamInputError(f"{name!r}: no such PLY under the server's --ply-root", "ply_path")
        return candidate

    def _full(self) -> Refusal:
        return Refusal(
            grpc.StatusCode.RESOURCE_EXHAUSTED,
            f"{len(self.sessions)} sessions open (at most {self.settings.max_sessions}); close one "
            f"(idle sessions expire after {self.settings.session_idle_timeout:g} s)",
        )

    @rpc
    def enhance(self, request: pb.EnhanceRequest, context: grpc.ServicerContext) -> pb.EnhanceReturn:
        with self._using(request.session_uuid) as session:
            if len(request.frames) > self.settings.max_cameras:
                raise StreamInputError(
                    f"{len(request.frames)} cameras in one tick; at most {self.settings.max_cameras}", ""
                )
            frames = from_views(request.frames, "frames")
            with session.lock:
                packet = session.stream.packet(frames)
                with self.model_lock.hold(request.session_uuid):
                    images = session.stream.enhance_packet(packet)
        return pb.EnhanceReturn(images=images_to_arrays(images))

    @rpc
    def close_session(self, request: pb.SessionId, context: grpc.ServicerContext) -> pb.Empty:
        self._check_id(request.session_uuid)
        with self._sessions_lock:
            removed = self.sessions.pop(request.session_uuid, None)
            if removed is None:
                raise self._missing(request.session_uuid)
        del removed
        release_freed_memory()
        return pb.Empty()

    @rpc
    def get_version(self, request: pb.Empty, context: grpc.ServicerContext) -> pb.VersionId:
        return pb.VersionId(
            version_id=__version__,
            checkpoint=str(getattr(self.enhancer, "checkpoint", "")),
            method=str(getattr(self.enhancer, "name", "")),
        )
