"""The gRPC enhancer server: sessions of :class:`~setdiff_bench.evaluation.stream.StreamSession` behind ``enhancer.proto``.

Behaviour under bad input and load:

* a malformed request (wrong image size or dtype, NaN values, non-rigid pose, too many cameras) is
  answered ``INVALID_ARGUMENT``, an unknown session ``NOT_FOUND``, each with a one-line message;
  the server keeps serving;
* an unexpected exception inside the server is answered ``INTERNAL`` with one line naming the RPC and
  an incident number; the traceback goes to the server's log only (never to the client);
* at most ``max_queue`` RPCs are in the server at once (running or waiting for a worker); grpc
  answers any beyond that ``RESOURCE_EXHAUSTED`` at once instead of queueing them;
* at most ``max_sessions`` sessions are open (``RESOURCE_EXHAUSTED`` beyond), each holding at most
  ``max_session_mib`` of references (checked at ``start_session``, ``RESOURCE_EXHAUSTED``);
* a session without a call for ``session_idle_timeout`` seconds (or the shorter lease its client asked
  for) expires: its memory is freed, its slot reused, and a later call on it gets ``NOT_FOUND`` saying
  it expired;
* with a token, every RPC but ``grpc.health.v1`` must carry ``authorization: Bearer <token>``;
  others are answered ``UNAUTHENTICATED`` before their request is decoded;
* sessions share the model: calls to it are serialised (outputs do not depend on concurrency) by a
  FIFO lock, so sessions calling at once take turns in arrival order and none starves;
* SIGTERM / SIGINT stop accepting RPCs, let in-flight ones finish (up to ``grace`` seconds), then exit.

Modules: :mod:`.servicer` (the RPC handlers and the session table), :mod:`.sessions` (a session's record,
the FIFO model lock, freeing memory), :mod:`.rpc_errors` (how failures are answered), :mod:`.auth` (the
bearer-token gate) and this module (binding, starting, stopping).
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Callable
from concurrent import futures
from dataclasses import dataclass, field
from typing import Any, Self

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.io.native_stderr import native_stderr_silenced
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve import enhancer_pb2_grpc as pb_grpc
from setdiff_bench.serve.auth import TokenInterceptor
from setdiff_bench.serve.rpc_errors import LOG
from setdiff_bench.serve.security import check_bind
from setdiff_bench.serve.servicer import EnhancerService
from setdiff_bench.serve.settings import ServeSettings

__all__ = [
    "MAX_MESSAGE_BYTES",
    "SERVICE_NAME",
    "RunningServer",
    "bind",
    "grpc_server",
    "pid_line",
    "serve_until_signalled",
    "start_server",
]

#: The fully qualified service name (health checks may ask for it).
SERVICE_NAME = pb.DESCRIPTOR.services_by_name["Enhancer"].full_name
#: Largest message either way (bytes): a 3-camera 576×1024 tick with float32 C-maps is ≈ 23 MB.
MAX_MESSAGE_BYTES = 256 * 1024 * 1024


@dataclass
class RunningServer:
    """A started server: ``port`` is the bound port."""

    server: grpc.Server
    port: int
    service: EnhancerService
    health: health.HealthServicer
    reaper_stop: threading.Event = field(default_factory=threading.Event)

    @classmethod
    def go_live(
        cls,
        server: grpc.Server,
        port: int,
        service: Any,
        health_servicer: health.HealthServicer,
        service_name: str,
        reaper_name: str,
    ) -> Self:
        """Start ``server``, report it and ``service_name`` SERVING to health checks, and expire ``service``'s idle
        sessions from a daemon thread named ``reaper_name`` until :meth:`stop`; the running server."""
        server.start()
        for name in ("", service_name):
            health_servicer.set(name, health_pb2.HealthCheckResponse.SERVING)
        running = cls(server, port, service, health_servicer)
        threading.Thread(
            target=_reap, args=(service, running.reaper_stop), name=reaper_name, daemon=True
        ).start()
        return running

    def stop(self, grace: float | None) -> None:
        """Refuse new RPCs, let in-flight ones finish for up to ``grace`` seconds, and wait."""
        self.reaper_stop.set()
        self.health.enter_graceful_shutdown()
        self.server.stop(grace).wait()


def _reap(service: EnhancerService, stop: threading.Event) -> None:
    """Expire idle sessions every quarter of the shortest lease (between 0.05 s and 1 s)."""
    while True:
        with service._sessions_lock:
            shortest = min((s.idle_timeout for s in service.sessions.values()), default=1.0)
        if stop.wait(min(1.0, max(0.05, shortest / 4))):
            return
        try:
            service.expire_idle()
        except Exception:  # pragma: no cover - keep reaping whatever happens
            LOG.exception("session reaper")


def start_server(
    enhancer: Any, settings: ServeSettings | None = None, *, clock: Callable[[], float] = time.monotonic
) -> RunningServer:
    """Bind and start the service (plus ``grpc.health.v1``) on ``settings.host:settings.port``.

    ``clock`` (seconds, monotonic) times idle expiry; tests pass one they move.

    Raises:
        UsageError: a non-loopback host without TLS and a token (and not ``insecure``).
        SetDiffBenchError: the address cannot be bound.
    """
    settings = settings or ServeSettings()
    check_bind(settings.host, settings.tls, settings.token, settings.insecure)
    server = grpc_server(settings, "enhance")
    service = EnhancerService(enhancer, settings, clock)
    pb_grpc.add_EnhancerServicer_to_server(service, server)
    health_servicer = health.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    port = bind(server, settings)
    return RunningServer.go_live(server, port, service, health_servicer, SERVICE_NAME, "session-reaper")


def serve_until_signalled(
    running: RunningServer, grace: float, ready: Callable[[], None] | None = None
) -> None:
    """Block until SIGTERM or SIGINT, then shut down gracefully (in-flight RPCs finish).

    Args:
        ready: called once the signal handlers are installed (``serve`` prints its "serving on" line
            there, so a SIGTERM sent as soon as a client reads it is a graceful stop, not a kill).
    """
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    if ready is not None:
        ready()
    stop.wait()
    running.stop(grace)


def pid_line(running: RunningServer, host: str) -> str:
    """The line ``serve`` prints once it listens (clients and tests read the port from it)."""
    tls = running.service.settings.tls
    mode = "plaintext" if tls is None else ("mutual TLS" if tls.client_ca is not None else "TLS")
    token = "token" if running.service.settings.token is not None else "no token"
    return f"serving on {host}:{running.port} (pid {os.getpid()}; {mode}, {token})"


def grpc_server(
    settings: ServeSettings, thread_prefix: str, max_message_bytes: int = MAX_MESSAGE_BYTES
) -> grpc.Server:
    """A gRPC server with the service's bounds: ``settings.workers`` threads, the token interceptor when a
    token is set, ``settings.max_queue`` concurrent RPCs, messages up to ``max_message_bytes``, no port
    sharing."""
    return grpc.server(
        futures.ThreadPoolExecutor(max_workers=settings.workers, thread_name_prefix=thread_prefix),
        interceptors=[TokenInterceptor(settings.token)] if settings.token is not None else None,
        maximum_concurrent_rpcs=settings.max_queue,
        options=[
            ("grpc.max_receive_message_length", max_message_bytes),
            ("grpc.max_send_message_length", max_message_bytes),
            ("grpc.so_reuseport", 0),
        ],
    )


def bind(server: grpc.Server, settings: ServeSettings) -> int:
    """Bind ``server`` to ``settings.host:port`` (TLS when ``settings.tls``); the bound port, or
    :class:`SetDiffBenchError` naming the address when it cannot be bound."""
    address = f"{settings.host}:{settings.port}"
    try:
        with native_stderr_silenced():
            if settings.tls is None:
                port = server.add_insecure_port(address)
            else:
                credentials = grpc.ssl_server_credentials(
                    [(settings.tls.private_key, settings.tls.cert_chain)],
                    root_certificates=settings.tls.client_ca,
                    require_client_auth=settings.tls.client_ca is not None,
                )
                port = server.add_secure_port(address, credentials)
    except RuntimeError:
        port = 0
    if port == 0:
        raise SetDiffBenchError("cannot bind (address in use or not available)", address)
    return port
