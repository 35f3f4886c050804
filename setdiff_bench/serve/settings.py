"""How ``setdiff-bench serve`` runs (no grpc or torch import, so ``serve --help`` answers at once)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from setdiff_bench.evaluation.tick_limits import MAX_CAMERAS_PER_TICK
from setdiff_bench.runtime.memory import FLOAT32_BYTES, VIEW_CHANNELS
from setdiff_bench.serve.security import ServerTls, TokenSource

DEFAULT_HOST = "127.0.0.1"

#: Bytes one reference of ``H × W`` pixels holds in a session, per pixel: float32 RGB (3), world C-map
#: (3) and alpha (1) -- the :class:`~setdiff_bench.evaluation.stream.StreamSession`'s ``ViewSet``.
SESSION_BYTES_PER_PIXEL = FLOAT32_BYTES * VIEW_CHANNELS


def reference_bytes(height: int, width: int) -> int:
    """Bytes one ``height × width`` reference holds in a session (:data:`SESSION_BYTES_PER_PIXEL` each pixel)."""
    return SESSION_BYTES_PER_PIXEL * height * width


@dataclass(frozen=True)
class ServeSettings:
    """How the server runs.

    Attributes:
        host: interface to bind (localhost by default; anything else needs ``tls`` and ``token``, or ``insecure``).
        port: TCP port; 0 = a free one (the bound port is returned by :func:`start_server`).
        workers: threads handling RPCs.
        max_queue: most RPCs in the server at once; more are refused with ``RESOURCE_EXHAUSTED`` (default
            two per session, so every open session can have one call running or waiting and one arriving).
        max_sessions: most open sessions.
        max_cameras: most frames one ``enhance`` may carry.
        grace: seconds in-flight RPCs get to finish on shutdown.
        cache_reference_latents: encode each session's references once (faster; outputs may then
            differ from the batch runner's by one 8-bit level, see :class:`~setdiff_bench.evaluation.stream.StreamSession`).
        session_idle_timeout: seconds without a call after which a session expires and its memory is freed
            (a simulator calls every tick, 0.05-0.5 s; 60 s outlives any pause of a live client and frees
            a crashed client's slot within a minute).  A client may ask for a shorter lease.
        max_session_mib: most memory one session's references may hold (MiB; each ``H × W`` reference
            holds :data:`SESSION_BYTES_PER_PIXEL` bytes a pixel, plus the session's PLY file size).
        tls: server certificate, key and optional client CA (mutual TLS); ``None``: plaintext.
        token: the bearer token every RPC but health must carry; ``None``: none asked.
        insecure: allow a non-loopback ``host`` without TLS and a token.
        ply_root: folder whose ``.ply`` files a session's ``ply_path`` may name (relative to it); ``None``:
            ``ply_path`` is refused (a client never names arbitrary files of the server's disk).
    """

    host: str = DEFAULT_HOST
    port: int = 50051
    workers: int = 4
    max_queue: int = 32
    max_sessions: int = 16
    max_cameras: int = MAX_CAMERAS_PER_TICK
    grace: float = 30.0
    cache_reference_latents: bool = False
    session_idle_timeout: float = 60.0
    max_session_mib: float = 256.0
    tls: ServerTls | None = None
    token: TokenSource | None = None
    insecure: bool = False
    ply_root: Path | None = None

    @property
    def max_session_bytes(self) -> int:
        return int(self.max_session_mib * 2**20)

    def worst_case_mib(self) -> float:
        """The references of all sessions at their bound: ``max_sessions × max_session_mib``."""
        return self.max_sessions * self.max_session_mib
