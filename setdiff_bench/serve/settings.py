"""How ``setdiff-bench serve`` runs (no grpc import, so the CLI can list the verb without grpcio)."""

from __future__ import annotations

from dataclasses import dataclass

from setdiff_bench.evaluation.stream import MAX_CAMERAS_PER_TICK

DEFAULT_HOST = "127.0.0.1"


@dataclass(frozen=True)
class ServeSettings:
    """How the server runs.

    Attributes:
        host: interface to bind (localhost by default; anything else exposes the service).
        port: TCP port; 0 = a free one (the bound port is returned by :func:`start_server`).
        workers: threads handling RPCs.
        max_queue: most RPCs in the server at once; more are refused with ``RESOURCE_EXHAUSTED``.
        max_sessions: most open sessions.
        max_cameras: most frames one ``enhance`` may carry.
        grace: seconds in-flight RPCs get to finish on shutdown.
        cache_reference_latents: encode each session's references once (faster; outputs may then
            differ from the batch runner's by one 8-bit level, see :class:`~setdiff_bench.evaluation.stream.StreamSession`).
    """

    host: str = DEFAULT_HOST
    port: int = 50051
    workers: int = 4
    max_queue: int = 8
    max_sessions: int = 16
    max_cameras: int = MAX_CAMERAS_PER_TICK
    grace: float = 30.0
    cache_reference_latents: bool = False
