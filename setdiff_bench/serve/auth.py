"""The enhancer server's bearer-token gate: a gRPC interceptor that lets through only RPCs carrying
``authorization: Bearer <token>`` (health checks always) and answers the others ``UNAUTHENTICATED``
before their request is decoded."""

from __future__ import annotations

from collections.abc import Callable

import grpc

from setdiff_bench.serve.security import TokenSource

#: RPCs answered without a token (load balancers and orchestrators probe health unauthenticated).
UNAUTHENTICATED_PREFIX = "/grpc.health.v1.Health/"


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
