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
"""

from __future__ import annotations

import collections
import functools
import logging
import os
import signal
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from concurrent import futures
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc

from setdiff_bench.errors import MemoryNeedError, SetDiffBenchError
from setdiff_bench.evaluation.stream import StreamInputError, StreamSession
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve import enhancer_pb2_grpc as pb_grpc
from setdiff_bench.serve.security import TokenSource, check_bind
from setdiff_bench.serve.settings import ServeSettings, reference_bytes
from setdiff_bench.serve.wire import from_views, images_to_arrays
from setdiff_bench.version import __version__

#: The fully qualified service name (health checks may ask for it).
SERVICE_NAME = pb.DESCRIPTOR.services_by_name["Enhancer"].full_name
#: Largest message either way (bytes): a 3-camera 576×1024 tick with float32 C-maps is ≈ 23 MB.
MAX_MESSAGE_BYTES = 256 * 1024 * 1024
#: RPCs answered without a token (load balancers and orchestrators probe health unauthenticated).
UNAUTHENTICATED_PREFIX = "/grpc.health.v1.Health/"
#: How many expired session ids are remembered (to answer "expired" rather than "unknown").
EXPIRED_MEMORY = 4096
#: Longest session id or PLY name a request may carry (characters; ours are 36-character UUIDs).
MAX_ID_CHARS = 64

LOG = logging.getLogger("setdiff_bench.serve")

Request = TypeVar("Request")
Reply = TypeVar("Reply")


class _Refusal(Exception):
    """A request the server refuses: answered with ``code`` and the one-line ``message``."""

    def __init__(self, code: grpc.StatusCode, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = " ".join(message.split())


def _rpc(
    method: Callable[[EnhancerService, Request, grpc.ServicerContext], Reply],
) -> Callable[[EnhancerService, Request, grpc.ServicerContext], Reply]:
    """Answer :class:`_Refusal` with its code, a tick too large for the memory with ``RESOURCE_EXHAUSTED``,
    any other :class:`SetDiffBenchError` with ``INVALID_ARGUMENT``,
    and anything else with ``INTERNAL`` plus an incident number (the traceback goes to the log only)."""

    @functools.wraps(method)
    def handler(self: EnhancerService, request: Request, context: grpc.ServicerContext) -> Reply:
        try:
            return method(self, request, context)
        except _Refusal as refusal:
            context.abort(refusal.code, refusal.message)
        except MemoryNeedError as error:  # the tick does not fit in the device's memory now
            context.abort(grpc.StatusCode.RESOURCE_EXHAUSTED, " ".join(error.one_line().split()))
        except SetDiffBenchError as error:
            context.abort(grpc.StatusCode.INVALID_ARGUMENT, " ".join(error.one_line().split()))
        except Exception:
            incident = uuid.uuid4().hex[:12]
            LOG.exception("incident %s: unexpected error in %s", incident, method.__name__)
            self.internal_errors += 1
            context.abort(
                grpc.StatusCode.INTERNAL,
                f"internal server error in {method.__name__} (incident {incident}; details in the server log)",
            )
        raise AssertionError("unreachable: context.abort raises")  # pragma: no cover

    return handler


class FairLock:
    """A FIFO lock: threads acquire it in the order they asked (Python's ``Lock`` promises no order).

    Each session holds its own lock while it waits here, so a session has at most one call waiting:
    FIFO over calls is round-robin over the sessions calling at once -- none waits for more than one
    call of each other session.  ``grants`` records the last owners served and ``arrivals`` the order in
    which each of them had asked (0, 1, 2, ...: increasing when FIFO holds), for tests and measurements.
    """

    def __init__(self, history: int = 4096) -> None:
        self._condition = threading.Condition()
        self._queue: collections.deque[int] = collections.deque()
        self._held = False
        self._asked = 0
        self.grants: collections.deque[str] = collections.deque(maxlen=history)
        self.arrivals: collections.deque[int] = collections.deque(maxlen=history)

    @contextmanager
    def hold(self, owner: str) -> Iterator[None]:
        with self._condition:
            ticket = self._asked
            self._asked += 1
            self._queue.append(ticket)
            while self._held or self._queue[0] != ticket:
                self._condition.wait()
            self._queue.popleft()
            self._held = True
            self.grants.append(owner)
            self.arrivals.append(ticket)
        try:
            yield
        finally:
            with self._condition:
                self._held = False
                self._condition.notify_all()


@dataclass
class _Session:
    stream: StreamSession
    idle_timeout: float
    held_bytes: int
    lock: threading.Lock = field(default_factory=threading.Lock)
    last_used: float = 0.0  # the service clock's time at the end of the last call
    busy: int = 0


def _load_malloc_trim() -> Callable[[int], int] | None:
    try:
        import ctypes

        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc: freed memory goes back as that allocator decides
        return None


_MALLOC_TRIM = _load_malloc_trim()


def release_freed_memory() -> None:
    """Hand memory freed by closed or expired sessions back to the OS (glibc keeps freed heap pages in its
    per-thread arenas otherwise, so the server's resident memory would stay at its peak).

    A session is freed by reference counting when it leaves the table (no cycles: tested); no
    ``gc.collect()`` here, which would hold the GIL for 0.1-1 s and stall every other call.  ctypes
    releases the GIL during ``malloc_trim`` (about 10 ms)."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


def _session_bytes(request: pb.StartSessionRequest) -> int:
    """Bytes the session's references will hold, from the request's shapes (before decoding anything)."""
    total = 0
    for view in request.references:
        shape = list(view.rgb.shape)
        if len(shape) == 3 and all(s > 0 for s in shape[:2]):
            total += reference_bytes(int(shape[0]), int(shape[1]))
    return total


class EnhancerService(pb_grpc.EnhancerServicer):
    """The RPC handlers; ``enhancer`` is a loaded SetDiff/DiFix enhancer."""

    def __init__(
        self, enhancer: Any, settings: ServeSettings, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.enhancer = enhancer
        self.settings = settings
        self.clock = clock  # seconds, monotonic (idle expiry)
        self.sessions: dict[str, _Session] = {}
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

    def _missing(self, session_uuid: str) -> _Refusal:
        timeout = self.expired.get(session_uuid)
        if timeout is not None:
            return _Refusal(
                grpc.StatusCode.NOT_FOUND,
                f"session {session_uuid!r} expired after {timeout:g} s without a call; start a new session",
            )
        return _Refusal(grpc.StatusCode.NOT_FOUND, f"unknown session {session_uuid!r}")

    @contextmanager
    def _using(self, session_uuid: str) -> Iterator[_Session]:
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
    @_rpc
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
        held = _session_bytes(request)
        ply = self._ply(request.ply_path) if request.ply_path else None
        if ply is not None:
            held += ply.stat().st_size
        if held > settings.max_session_bytes:
            raise _Refusal(
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
        session = _Session(
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

    def _full(self) -> _Refusal:
        return _Refusal(
            grpc.StatusCode.RESOURCE_EXHAUSTED,
            f"{len(self.sessions)} sessions open (at most {self.settings.max_sessions}); close one "
            f"(idle sessions expire after {self.settings.session_idle_timeout:g} s)",
        )

    @_rpc
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

    @_rpc
    def close_session(self, request: pb.SessionId, context: grpc.ServicerContext) -> pb.Empty:
        self._check_id(request.session_uuid)
        with self._sessions_lock:
            removed = self.sessions.pop(request.session_uuid, None)
            if removed is None:
                raise self._missing(request.session_uuid)
        del removed
        release_freed_memory()
        return pb.Empty()

    @_rpc
    def get_version(self, request: pb.Empty, context: grpc.ServicerContext) -> pb.VersionId:
        return pb.VersionId(
            version_id=__version__,
            checkpoint=str(getattr(self.enhancer, "checkpoint", "")),
            method=str(getattr(self.enhancer, "name", "")),
        )


def _deny(message: str) -> grpc.RpcMethodHandler:
    def refuse(request: bytes, context: grpc.ServicerContext) -> None:
        context.abort(grpc.StatusCode.UNAUTHENTICATED, message)

    # no deserializer: the request stays raw bytes, nothing of it is decoded or processed
    return grpc.unary_unary_rpc_method_handler(refuse)


class TokenInterceptor(grpc.ServerInterceptor):
    """Let through only RPCs carrying ``authorization: Bearer <token>`` (health checks always)."""

    def __init__(self, token: TokenSource) -> None:
        self.token = token
        self.refused = 0
        self._missing = _deny("missing bearer token (metadata 'authorization: Bearer <token>')")
        self._wrong = _deny("wrong or expired bearer token")

    def intercept_service(
        self,
        continuation: Callable[[grpc.HandlerCallDetails], grpc.RpcMethodHandler | None],
        details: grpc.HandlerCallDetails,
    ) -> grpc.RpcMethodHandler | None:
        if details.method.startswith(UNAUTHENTICATED_PREFIX):
            return continuation(details)
        given = [value for key, value in details.invocation_metadata or () if key == "authorization"]
        if len(given) == 1 and isinstance(given[0], str) and given[0].startswith("Bearer "):
            if self.token.accepts(given[0][len("Bearer ") :]):
                return continuation(details)
            self.refused += 1
            return self._wrong
        self.refused += 1
        return self._missing


@dataclass
class RunningServer:
    """A started server: ``port`` is the bound port."""

    server: grpc.Server
    port: int
    service: EnhancerService
    health: health.HealthServicer
    reaper_stop: threading.Event = field(default_factory=threading.Event)

    def stop(self, grace: float | None) -> None:
        """Refuse new RPCs, let in-flight ones finish for up to ``grace`` seconds, and wait."""
        self.reaper_stop.set()
        self.health.enter_graceful_shutdown()
        self.server.stop(grace).wait()


@contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Silence file descriptor 2 (grpc core logs a bind failure there itself; ours is the one line)."""
    try:
        saved = os.dup(2)
    except OSError:  # no stderr at all
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


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
    server = grpc.server(
        futures.ThreadPoolExecutor(max_workers=settings.workers, thread_name_prefix="enhance"),
        interceptors=[TokenInterceptor(settings.token)] if settings.token is not None else None,
        maximum_concurrent_rpcs=settings.max_queue,
        options=[
            ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
            ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
            ("grpc.so_reuseport", 0),
        ],
    )
    service = EnhancerService(enhancer, settings, clock)
    pb_grpc.add_EnhancerServicer_to_server(service, server)
    health_servicer = health.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    address = f"{settings.host}:{settings.port}"
    try:
        with _quiet_stderr():
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
        raise SetDiffBenchError("cannot bind (address in use or not available)", address) from None
    if port == 0:
        raise SetDiffBenchError("cannot bind (address in use or not available)", address)
    server.start()
    for name in ("", SERVICE_NAME):
        health_servicer.set(name, health_pb2.HealthCheckResponse.SERVING)
    running = RunningServer(server, port, service, health_servicer)
    threading.Thread(
        target=_reap, args=(service, running.reaper_stop), name="session-reaper", daemon=True
    ).start()
    return running


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
