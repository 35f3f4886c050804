"""``setdiff-bench serve``: the SetDiff (or DiFix) enhancer as a gRPC service for simulators.

See :mod:`setdiff_bench.serve.server` for the RPCs and behaviour under bad input and load, and
:mod:`setdiff_bench.serve.security` for TLS, the bearer token and the bind rule.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import get_args

from setdiff_bench.cli import add_device_argument
from setdiff_bench.models.setdiff.methods import Method
from setdiff_bench.serve.settings import DEFAULT_HOST, SESSION_BYTES_PER_PIXEL, ServeSettings

VERB = "serve"
HELP = "serve a SetDiff/DiFix checkpoint over gRPC (start_session / enhance / close_session, health)"
_DEFAULTS = ServeSettings()
DESCRIPTION = (
    "Serve a trained enhancer over gRPC for closed-loop simulation: a client opens a session with a "
    "scene's recorded references, then sends each tick's rendered frames and gets them enhanced. "
    f"Binds to {DEFAULT_HOST} by default; any other address needs TLS (--tls-cert, --tls-key) and a "
    "bearer token (--token-file or $SETDIFF_SERVE_TOKEN), or --insecure. "
    "SIGTERM finishes in-flight requests and exits.\n\n"
    f"Memory: a session holds {SESSION_BYTES_PER_PIXEL} bytes per reference pixel (float32 RGB, C-map, "
    f"alpha; 15.75 MiB per 576x1024 reference) plus its PLY; at most --max-session-mib each, so the "
    f"references of all sessions take at most --max-sessions x --max-session-mib "
    f"({_DEFAULTS.max_sessions} x {_DEFAULTS.max_session_mib:g} MiB = "
    f"{_DEFAULTS.worst_case_mib() / 1024:g} GiB at the defaults), plus the model and up to --max-queue "
    "requests in flight (at most 256 MiB each).\n\n"
    "Deployment (certificate, token, host): docs/serve.md.\n\n"
    "Examples:\n\n"
    "    setdiff-bench serve --checkpoint tiny_setdiff --port 50051\n"
    "    setdiff-bench serve --checkpoint tiny_setdiff --host 0.0.0.0 --port 50051 "
    "--tls-cert server.pem --tls-key server.key --token-file token"
)

#: The integer settings that must be >= 1: each is an option ``--name`` whose help starts with this text.
LIMITS: dict[str, str] = {
    "workers": "RPC threads",
    "max_queue": "most RPCs in the server at once; more get RESOURCE_EXHAUSTED",
    "max_sessions": "most open sessions; more get RESOURCE_EXHAUSTED until one closes or expires",
    "max_cameras": "most frames per tick",
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    defaults = _DEFAULTS
    parser.add_argument("--checkpoint", required=True, help="checkpoint folder (or training output folder)")
    parser.add_argument(
        "--method",
        default="setdiff",
        choices=get_args(Method),
        help="what the checkpoint was trained as (default %(default)s; `weights list` shows the shipped ones)",
    )
    parser.add_argument("--host", default=defaults.host, help="interface to bind (default %(default)s)")
    parser.add_argument(
        "--port", type=int, default=defaults.port, help="TCP port; 0 = a free one (default %(default)s)"
    )
    for name, what in LIMITS.items():
        parser.add_argument(
            f"--{name.replace('_', '-')}",
            type=int,
            default=getattr(defaults, name),
            help=f"{what} (default %(default)s)",
        )
    parser.add_argument(
        "--session-idle-timeout",
        type=float,
        default=defaults.session_idle_timeout,
        help="seconds without a call after which a session expires and its memory is freed (a simulator "
        "calls every tick, 0.05-0.5 s; default %(default)s); a client may ask for a shorter lease",
    )
    parser.add_argument(
        "--max-session-mib",
        type=float,
        default=defaults.max_session_mib,
        help=f"most memory one session's references may hold, MiB ({SESSION_BYTES_PER_PIXEL} bytes per "
        "reference pixel, plus its PLY); larger sessions are refused at start_session (default %(default)s)",
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
    parser.add_argument("--tls-cert", type=Path, default=None, help="PEM server certificate chain (TLS)")
    parser.add_argument("--tls-key", type=Path, default=None, help="PEM server private key (TLS)")
    parser.add_argument(
        "--tls-client-ca",
        type=Path,
        default=None,
        help="PEM CA certificate: clients must present a certificate it signed (mutual TLS)",
    )
    parser.add_argument(
        "--token-file",
        type=Path,
        default=None,
        help="file holding the bearer token every RPC but health must carry (re-read when it changes); "
        "default $SETDIFF_SERVE_TOKEN if set. Never give the token itself as an argument",
    )
    parser.add_argument(
        "--ply-root",
        type=Path,
        default=None,
        help="folder of scene PLYs a session may name (ply_path, relative to it) to render C-maps the client "
        "does not send; default: none (sessions must send C-maps)",
    )
    # a token given as an argument shows in `ps` to every user: refused without echoing it (and without
    # argparse taking `--token X` as an abbreviation of --token-file)
    parser.add_argument("--token", dest="token_argument", default=None, help=argparse.SUPPRESS)
    parser.add_argument(
        "--insecure",
        action="store_true",
        help="allow a non-loopback --host without TLS and a token (anyone reaching the port may use it)",
    )
    add_device_argument(parser, "where the enhancer runs")
    parser.add_argument("--dtype", default=None, help="float32 / bfloat16 / float16")


def settings_from_arguments(args: argparse.Namespace) -> ServeSettings:
    """Validate the options (certificates and token read, bind rule applied) into settings.

    Raises:
        UsageError: a bad value, an unreadable certificate / key / token, or a non-loopback host
            without TLS and a token (one line; nothing is started).
    """
    from setdiff_bench.errors import UsageError
    from setdiff_bench.serve.security import ServerTls, check_bind, token_source

    if getattr(args, "token_argument", None) is not None:
        raise UsageError(
            "never give the token on the command line (every user sees it in `ps`); "
            "put it in a file for --token-file or in $SETDIFF_SERVE_TOKEN",
            "--token",
        )
    for name in LIMITS:
        if getattr(args, name) < 1:
            raise UsageError(f"must be >= 1, got {getattr(args, name)}", f"--{name.replace('_', '-')}")
    if not 0 <= args.port <= 65535:
        raise UsageError(f"must be 0..65535, got {args.port}", "--port")
    for name in ("session_idle_timeout", "max_session_mib", "grace"):
        value = getattr(args, name)
        if not math.isfinite(value) or value < 0 or (value == 0 and name != "grace"):
            raise UsageError(f"must be a finite number > 0, got {value}", f"--{name.replace('_', '-')}")
    if args.ply_root is not None and not args.ply_root.is_dir():
        raise UsageError("not a folder", args.ply_root)
    tls = ServerTls.from_files(args.tls_cert, args.tls_key, args.tls_client_ca)
    token = token_source(args.token_file)
    check_bind(args.host, tls, token, args.insecure)
    return ServeSettings(
        host=args.host,
        port=args.port,
        workers=args.workers,
        max_queue=args.max_queue,
        max_sessions=args.max_sessions,
        max_cameras=args.max_cameras,
        grace=args.grace,
        cache_reference_latents=args.cache_reference_latents,
        session_idle_timeout=args.session_idle_timeout,
        max_session_mib=args.max_session_mib,
        tls=tls,
        token=token,
        insecure=args.insecure,
        ply_root=args.ply_root,
    )


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    settings = settings_from_arguments(args)  # before the model loads: a refusal costs nothing
    from setdiff_bench.enhancers.setdiff import load_enhancer
    from setdiff_bench.runtime.devices import resolve_device
    from setdiff_bench.serve.server import pid_line, serve_until_signalled, start_server

    enhancer = load_enhancer(
        args.method, args.checkpoint, device=resolve_device(args.device), dtype=args.dtype
    )
    running = start_server(enhancer, settings)
    serve_until_signalled(running, args.grace, ready=lambda: print(pid_line(running, args.host), flush=True))
    print("stopped", flush=True)
    return 0
