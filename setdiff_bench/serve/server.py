"""The gRPC enhancer server: sessions of :class:`~setdiff_bench.evaluation.stream.StreamSession` behind ``enhancer.proto``.

Behaviour under bad input and load:

* a malformed request (wrong image size or dtype, NaN values, non-rigid pose, too many cameras) is
  answered ``INVALID_ARGUMENT``, an unknown session ``NOT_FOUND``, each with a one-line message;
  the server keeps serving;
* at most ``max_queue`` RPCs are in the server at once (running or waiting for a worker); grpc
  answers any beyond that ``RESOURCE_EXHAUSTED`` at once instead of queueing them;
* at most ``max_sessions`` sessions are open (``RESOURCE_EXHAUSTED`` beyond);
* SIGTERM / SIGINT stop accepting RPCs, let in-flight ones finish (up to ``grace`` seconds), then exit;
* sessions share the model (calls to it are serialised, so outputs do not depend on concurrency)
  but nothing else: each has its own references and tick counter.
"""

from __future__ import annotations

import os
import signal
import threading
import uuid
from concurrent import futures
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc

from setdiff_bench import __version__
from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.evaluation.stream import StreamInputError, StreamSession
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve import enhancer_pb2_grpc as pb_grpc
from setdiff_bench.serve.settings import ServeSettings
from setdiff_bench.serve.wire import from_views, images_to_arrays

#: The fully qualified service name (health checks may ask for it).
SERVICE_NAME = pb.DESCRIPTOR.services_by_name["Enhancer"].full_name
#: Largest message either way (bytes): a 3-camera 576×1024 tick with float32 C-maps is ≈ 23 MB.
MAX_MESSAGE_BYTES = 256 * 1024 * 1024


@dataclass
class _Session:
    stream: StreamSession
    lock: threading.Lock = field(default_factory=threading.Lock)


class EnhancerService(pb_grpc.EnhancerServicer):
    """The RPC handlers; ``enhancer`` is a loaded SetDiff/DiFix enhancer."""

    def __init__(self, enhancer: Any, settings: ServeSettings) -> None:
        self.enhancer = enhancer
        self.settings = settings
        self.sessions: dict[str, _Session] = {}
        self._sessions_lock = threading.Lock()
        self._model_lock = threading.Lock()

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _refuse(context: grpc.ServicerContext, code: grpc.StatusCode, message: str) -> None:
        context.abort(code, " ".join(message.split()))

    def _session(self, session_uuid: str, context: grpc.ServicerContext) -> _Session:
        with self._sessions_lock:
            session = self.sessions.get(session_uuid)
        if session is None:
            self._refuse(context, grpc.StatusCode.NOT_FOUND, f"unknown session {session_uuid!r}")
        return session

    # ------------------------------------------------------------------ RPCs
    def start_session(self, request: pb.StartSessionRequest, context: grpc.ServicerContext) -> pb.SessionId:
        try:
            if request.max_references < 0:
                raise StreamInputError(
                    f"max_references must be >= 0, got {request.max_references}", "max_references"
                )
            ply = None
            if request.ply_path:
                ply = Path(request.ply_path)
                if not ply.is_file():
                    raise StreamInputError("PLY not found on the server", ply)
            references = from_views(request.references, "references")
            stream = StreamSession(
                self.enhancer,
                references,
                ply=ply,
                max_references=request.max_references or None,
                max_cameras=self.settings.max_cameras,
                cache_reference_latents=self.settings.cache_reference_latents,
            )
        except SetDiffBenchError as error:
            self._refuse(context, grpc.StatusCode.INVALID_ARGUMENT, error.one_line())
        with self._sessions_lock:
            if len(self.sessions) >= self.settings.max_sessions:
                self._refuse(
                    context,
                    grpc.StatusCode.RESOURCE_EXHAUSTED,
                    f"{len(self.sessions)} sessions open (at most {self.settings.max_sessions}); close one",
                )
            session_uuid = str(uuid.uuid4())
            self.sessions[session_uuid] = _Session(stream)
        return pb.SessionId(session_uuid=session_uuid)

    def enhance(self, request: pb.EnhanceRequest, context: grpc.ServicerContext) -> pb.EnhanceReturn:
        session = self._session(request.session_uuid, context)
        if len(request.frames) > self.settings.max_cameras:
            self._refuse(
                context,
                grpc.StatusCode.INVALID_ARGUMENT,
                f"{len(request.frames)} cameras in one tick; at most {self.settings.max_cameras}",
            )
        try:
            frames = from_views(request.frames, "frames")
            with session.lock:
                packet = session.stream.packet(frames)
                with self._model_lock:
                    images = session.stream.enhance_packet(packet)
        except SetDiffBenchError as error:
            self._refuse(context, grpc.StatusCode.INVALID_ARGUMENT, error.one_line())
        return pb.EnhanceReturn(images=images_to_arrays(images))

    def close_session(self, request: pb.SessionId, context: grpc.ServicerContext) -> pb.Empty:
        with self._sessions_lock:
            removed = self.sessions.pop(request.session_uuid, None)
        if removed is None:
            self._refuse(context, grpc.StatusCode.NOT_FOUND, f"unknown session {request.session_uuid!r}")
        return pb.Empty()

    def get_version(self, request: pb.Empty, context: grpc.ServicerContext) -> pb.VersionId:
        return pb.VersionId(
            version_id=__version__,
            checkpoint=str(getattr(self.enhancer, "checkpoint", "")),
            method=str(getattr(self.enhancer, "name", "")),
        )


@dataclass
class RunningServer:
    """A started server: ``port`` is the bound port."""

    server: grpc.Server
    port: int
    service: EnhancerService
    health: health.HealthServicer

    def stop(self, grace: float | None) -> None:
        """Refuse new RPCs, let in-flight ones finish for up to ``grace`` seconds, and wait."""
        self.health.enter_graceful_shutdown()
        self.server.stop(grace).wait()


def start_server(enhancer: Any, settings: ServeSettings | None = None) -> RunningServer:
    """Bind and start the service (plus ``grpc.health.v1``) on ``settings.host:settings.port``.

    Raises:
        SetDiffBenchError: the address cannot be bound.
    """
    settings = settings or ServeSettings()
    server = grpc.server(
        futures.ThreadPoolExecutor(max_workers=settings.workers, thread_name_prefix="enhance"),
        maximum_concurrent_rpcs=settings.max_queue,
        options=[
            ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
            ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
            ("grpc.so_reuseport", 0),
        ],
    )
    service = EnhancerService(enhancer, settings)
    pb_grpc.add_EnhancerServicer_to_server(service, server)
    health_servicer = health.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    address = f"{settings.host}:{settings.port}"
    try:
        port = server.add_insecure_port(address)
    except RuntimeError as error:
        raise SetDiffBenchError(f"cannot bind ({error})", address) from None
    if port == 0:
        raise SetDiffBenchError("cannot bind (address in use or not available)", address)
    server.start()
    for name in ("", SERVICE_NAME):
        health_servicer.set(name, health_pb2.HealthCheckResponse.SERVING)
    return RunningServer(server, port, service, health_servicer)


def serve_until_signalled(running: RunningServer, grace: float) -> None:
    """Block until SIGTERM or SIGINT, then shut down gracefully (in-flight RPCs finish)."""
    stop = threading.Event()
    for signum in (signal.SIGTERM, signal.SIGINT):
        signal.signal(signum, lambda *_: stop.set())
    stop.wait()
    running.stop(grace)


def pid_line(running: RunningServer, host: str) -> str:
    """The line ``serve`` prints once it listens (clients and tests read the port from it)."""
    return f"serving on {host}:{running.port} (pid {os.getpid()})"
