"""How the enhancer server answers an RPC that fails: a :class:`Refusal` with its own status code and
one-line message, a tick too large for the memory ``RESOURCE_EXHAUSTED``, any other toolkit error
``INVALID_ARGUMENT``, and anything unexpected ``INTERNAL`` with an incident number (traceback to the log
only) -- the :func:`rpc` decorator every handler of
:class:`~setdiff_bench.serve.servicer.EnhancerService` wears."""

from __future__ import annotations

import functools
import logging
import uuid
from collections.abc import Callable
from typing import TYPE_CHECKING, TypeVar

import grpc

from setdiff_bench.errors import MemoryNeedError, SetDiffBenchError

if TYPE_CHECKING:
    from setdiff_bench.serve.servicer import EnhancerService

#: The service's logger (every serve module logs through this one).
LOG = logging.getLogger("setdiff_bench.serve")

Request = TypeVar("Request")
Reply = TypeVar("Reply")


class Refusal(Exception):
    """A request the server refuses: answered with ``code`` and the one-line ``message``."""

    def __init__(self, code: grpc.StatusCode, message: str) -> None:
        super().__init__(message)
        self.code = code
        self.message = " ".join(message.split())


def rpc(
    method: Callable[[EnhancerService, Request, grpc.ServicerContext], Reply],
) -> Callable[[EnhancerService, Request, grpc.ServicerContext], Reply]:
    """Answer :class:`Refusal` with its code, a tick too large for the memory with ``RESOURCE_EXHAUSTED``,
    any other :class:`SetDiffBenchError` with ``INVALID_ARGUMENT``,
    and anything else with ``INTERNAL`` plus an incident number (the traceback goes to the log only)."""

    @functools.wraps(method)
    def handler(self: EnhancerService, request: Request, context: grpc.ServicerContext) -> Reply:
        try:
            return method(self, request, context)
        except Refusal as refusal:
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
