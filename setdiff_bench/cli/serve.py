"""``setdiff-bench serve``: the SetDiff (or DiFix) enhancer as a gRPC service for simulators.

See :mod:`setdiff_bench.serve.server` for the RPCs and behaviour under bad input and load.
"""

from __future__ import annotations

import argparse
from dataclasses import fields

from setdiff_bench.cli import add_device_argument
from setdiff_bench.serve.settings import DEFAULT_HOST, ServeSettings

VERB = "serve"
HELP = "serve a SetDiff/DiFix checkpoint over gRPC (start_session / enhance / close_session, health)"
DESCRIPTION = (
    "Serve a trained enhancer over gRPC for closed-loop simulation: a client opens a session with a "
    "scene's recorded references, then sends each tick's rendered frames and gets them enhanced. "
    f"Binds to {DEFAULT_HOST} by default. SIGTERM finishes in-flight requests and exits."
)

#: The integer settings that must be >= 1: each is an option ``--name`` whose help starts with this text.
LIMITS: dict[str, str] = {
    "workers": "RPC threads",
    "max_queue": "most RPCs in the server at once; more get RESOURCE_EXHAUSTED",
    "max_sessions": "",
    "max_cameras": "most frames per tick",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = ServeSettings()
    parser.add_argument("--checkpoint", required=True, help="checkpoint folder (or training output folder)")
    parser.add_argument("--method", default="setdiff", choices=("setdiff", "difix"))
    parser.add_argument("--host", default=defaults.host, help="interface to bind (default %(default)s)")
    parser.add_argument(
        "--port", type=int, default=defaults.port, help="TCP port; 0 = a free one (default %(default)s)"
    )
    for name, what in LIMITS.items():
        parser.add_argument(
            f"--{name.replace('_', '-')}",
            type=int,
            default=getattr(defaults, name),
            help=f"{what} (default %(default)s)".lstrip(),
        )
    parser.add_argument(
        "--grace",
        type=float,
        default=defaults.grace,
        help="seconds in-flight requests get on shutdown (default %(default)s)",
    )
    parser.add_argument(
        "--cache-reference-latents",
        action="store_true",
        help="encode each session's references once (faster; outputs may differ from "
        "`run --method setdiff` by one 8-bit level)",
    )
    add_device_argument(parser, "where the enhancer runs")
    parser.add_argument("--dtype", default=None, help="float32 / bfloat16 / float16")


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.enhancers.setdiff import load_enhancer
    from setdiff_bench.errors import UsageError
    from setdiff_bench.runtime.devices import resolve_device
    from setdiff_bench.serve.server import pid_line, serve_until_signalled, start_server

    for name in LIMITS:
        if getattr(args, name) < 1:
            raise UsageError(f"must be >= 1, got {getattr(args, name)}", f"--{name.replace('_', '-')}")
    if not 0 <= args.port <= 65535:
        raise UsageError(f"must be 0..65535, got {args.port}", "--port")
    enhancer = load_enhancer(
        args.method, args.checkpoint, device=resolve_device(args.device), dtype=args.dtype
    )
    settings = ServeSettings(**{field.name: getattr(args, field.name) for field in fields(ServeSettings)})
    running = start_server(enhancer, settings)
    print(pid_line(running, args.host), flush=True)
    serve_until_signalled(running, args.grace)
    print("stopped", flush=True)
    return 0
