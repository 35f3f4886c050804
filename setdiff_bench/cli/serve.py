"""``setdiff-bench serve``: the SetDiff (or DiFix) enhancer as a gRPC service for simulators.

See :mod:`setdiff_bench.serve.server` for the RPCs and behaviour under bad input and load, and
:mod:`setdiff_bench.serve.security` for TLS, the bearer token and the bind rule.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import get_args

from setdiff_bench.cli import add_device_argument, settings_from
from setdiff_bench.models.setdiff.methods import Method
from setdiff_bench.serve.sensorsim.settings import ROLES, SensorsimSettings
from setdiff_bench.serve.settings import DEFAULT_HOST, SESSION_BYTES_PER_PIXEL, ServeSettings

VERB = "serve"
HELP = "serve a SetDiff/DiFix checkpoint over gRPC (start_session / enhance / close_session, health)"
_DEFAULTS = ServeSettings()
_SENSORSIM = SensorsimSettings()
PROTOCOLS = ("setdiff", "sensorsim")
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
    "With --protocol sensorsim it speaks AlpaSim's renderer protocol (NuRec's SensorsimService) instead: "
    "--role renderer renders the fitted scenes of --scenes DIR (enhanced in place with --checkpoint), "
    "--role proxy --upstream HOST:PORT forwards every call to another sensorsim renderer and enhances the "
    "images it returns with each scene's recorded frames (docs/serve.md, 'AlpaSim drop-in').\n\n"
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
    parser.add_argument(
        "--checkpoint",
        default=None,
        help="checkpoint folder (or training output folder); required but by the sensorsim renderer, "
        "which renders plain 3DGS without one",
    )
    parser.add_argument(
        "--protocol",
        default="setdiff",
        choices=PROTOCOLS,
        help="setdiff: this toolkit's enhancer protocol; sensorsim: AlpaSim's renderer protocol (default %(default)s)",
    )
    parser.add_argument(
        "--role",
        default=_SENSORSIM.role,
        choices=ROLES,
        help="sensorsim only: renderer (render --scenes) or proxy (forward to --upstream and enhance; default %(default)s)",
    )
    parser.add_argument(
        "--scenes",
        type=Path,
        default=None,
        help="sensorsim only: folder of fitted scenes, <scenes>/<scene_id>/ with scene.ply (or fits/lane0.ply) and "
        "its recorded frames in a layout the loaders read",
    )
    parser.add_argument(
        "--upstream",
        default=None,
        help="sensorsim proxy only: HOST:PORT of the sensorsim renderer to forward to",
    )
    parser.add_argument(
        "--upstream-timeout",
        type=float,
        default=_SENSORSIM.upstream_timeout,
        help="sensorsim proxy only: seconds to wait for the upstream renderer per call; past it the call's cameras "
        "fail (default %(default)s)",
    )
    parser.add_argument(
        "--upstream-same-format",
        action="store_true",
        help="sensorsim proxy only: forward the client's image format and quality instead of asking the upstream "
        "renderer for lossless PNG",
    )
    parser.add_argument(
        "--max-loaded-scenes",
        type=int,
        default=_SENSORSIM.max_loaded_scenes,
        help="sensorsim only: scenes kept loaded at once (default %(default)s)",
    )
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
    return settings_from(ServeSettings, args, tls=tls, token=token)


def sensorsim_settings_from_arguments(args: argparse.Namespace) -> SensorsimSettings:
    """The ``--protocol sensorsim`` options (plus the common ones) validated into settings.

    Raises:
        UsageError: no or a missing ``--scenes`` folder, a proxy without ``--upstream HOST:PORT`` or without
            ``--checkpoint``, a bad timeout or scene count, or any refusal of :func:`settings_from_arguments`.
    """
    from setdiff_bench.errors import UsageError

    serve = settings_from_arguments(args)
    if args.scenes is None or not args.scenes.is_dir():
        raise UsageError(
            "--protocol sensorsim needs a folder of fitted scenes" if args.scenes is None else "not a folder",
            args.scenes or "--scenes",
        )
    if args.role == "proxy":
        host, _, port = (args.upstream or "").rpartition(":")
        if not host or not port.isdigit() or not 0 < int(port) <= 65535:
            raise UsageError(f"give the upstream renderer as HOST:PORT, got {args.upstream!r}", "--upstream")
        if args.checkpoint is None:
            raise UsageError("the proxy enhances: give the enhancer's checkpoint", "--checkpoint")
    if not math.isfinite(args.upstream_timeout) or args.upstream_timeout <= 0:
        raise UsageError(f"must be a finite number > 0, got {args.upstream_timeout}", "--upstream-timeout")
    if args.max_loaded_scenes < 1:
        raise UsageError(f"must be >= 1, got {args.max_loaded_scenes}", "--max-loaded-scenes")
    return SensorsimSettings(
        serve=serve,
        role=args.role,
        scenes=args.scenes,
        upstream=args.upstream if args.role == "proxy" else None,
        upstream_timeout=args.upstream_timeout,
        upstream_png=not args.upstream_same_format,
        max_loaded_scenes=args.max_loaded_scenes,
    )


def run_sensorsim(args: argparse.Namespace) -> int:
    """``serve --protocol sensorsim``: start the role, print the serving line, stop on SIGTERM / SIGINT."""
    settings = sensorsim_settings_from_arguments(args)  # before the model loads: a refusal costs nothing
    from setdiff_bench.runtime.devices import resolve_device
    from setdiff_bench.serve.sensorsim.server import sensorsim_pid_line, start_sensorsim
    from setdiff_bench.serve.server import serve_until_signalled

    enhancer = None
    if args.checkpoint is not None:
        from setdiff_bench.enhancers.setdiff import load_enhancer

        enhancer = load_enhancer(
            args.method, args.checkpoint, device=resolve_device(args.device), dtype=args.dtype
        )
    running = start_sensorsim(settings, enhancer)
    serve_until_signalled(
        running, args.grace, ready=lambda: print(sensorsim_pid_line(running, args.host), flush=True)
    )
    print("stopped", flush=True)
    return 0


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    if args.protocol == "sensorsim":
        return run_sensorsim(args)
    if args.checkpoint is None:
        from setdiff_bench.errors import UsageError

        raise UsageError("the enhancer service needs a checkpoint", "--checkpoint")
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
