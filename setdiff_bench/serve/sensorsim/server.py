"""Bind and start the sensorsim service (either role) with the enhancer server's gates: the bind rule (a
non-loopback host needs TLS and a token, or ``insecure``), TLS / mutual TLS, the bearer token, ``max_queue``,
``grpc.health.v1``, the session reaper, 64 MiB messages and a graceful stop."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from grpc_health.v1 import health, health_pb2_grpc

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.serve.security import check_bind
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb
from setdiff_bench.serve.sensorsim import sensorsim_pb2_grpc as pb_grpc
from setdiff_bench.serve.sensorsim.service import ProxyService, RendererService, SensorsimBase
from setdiff_bench.serve.sensorsim.settings import MAX_MESSAGE_BYTES, SensorsimSettings
from setdiff_bench.serve.server import RunningServer, bind, grpc_server

#: The fully qualified service name (AlpaSim's and NuRec's).
SERVICE_NAME = pb.DESCRIPTOR.services_by_name["SensorsimService"].full_name


@dataclass
class RunningSensorsim(RunningServer):
    """A started sensorsim server (:class:`RunningServer` with the role's servicer); stopping it also closes
    the proxy's upstream channel."""

    service: SensorsimBase  # type: ignore[assignment]

    def stop(self, grace: float | None) -> None:
        """Refuse new RPCs, let in-flight ones finish for up to ``grace`` seconds, close the upstream channel."""
        super().stop(grace)
        if isinstance(self.service, ProxyService):
            self.service.close()
        if self.service.enhancement is not None:
            self.service.enhancement.close_all()


def start_sensorsim(
    settings: SensorsimSettings, enhancer: Any | None = None, *, clock: Callable[[], float] = time.monotonic
) -> RunningSensorsim:
    """Start the role ``settings.role`` on ``settings.serve.host:port`` (plus ``grpc.health.v1``).

    Args:
        enhancer: a loaded SetDiff / DiFix enhancer; required by the proxy, optional for the renderer
            (``None``: plain 3DGS renders).

    Raises:
        UsageError: a non-loopback host without TLS and a token (and not ``insecure``), no scenes folder,
            a proxy without upstream or enhancer.
        SetDiffBenchError: the address cannot be bound.
    """
    serve = settings.serve
    check_bind(serve.host, serve.tls, serve.token, serve.insecure)
    if settings.role == "proxy":
        if enhancer is None:
            raise SetDiffBenchError("the proxy enhances: give it a checkpoint", "--checkpoint")
        service: SensorsimBase = ProxyService(settings, enhancer, clock)
    else:
        service = RendererService(settings, enhancer, clock)
    server = grpc_server(serve, "sensorsim", MAX_MESSAGE_BYTES)
    pb_grpc.add_SensorsimServiceServicer_to_server(service, server)
    health_servicer = health.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    try:
        port = bind(server, serve)
    except SetDiffBenchError:
        if isinstance(service, ProxyService):
            service.close()
        raise
    return RunningSensorsim.go_live(server, port, service, health_servicer, SERVICE_NAME, "sensorsim-reaper")


def sensorsim_pid_line(running: RunningSensorsim, host: str) -> str:
    """The line ``serve --protocol sensorsim`` prints once it listens (tests read the port from it)."""
    import os

    serve = running.service.settings.serve
    mode = "plaintext" if serve.tls is None else ("mutual TLS" if serve.tls.client_ca is not None else "TLS")
    token = "token" if serve.token is not None else "no token"
    return f"serving on {host}:{running.port} (pid {os.getpid()}; sensorsim {running.service.role}; {mode}, {token})"
