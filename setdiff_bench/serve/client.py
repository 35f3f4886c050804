"""A small Python client of ``setdiff-bench serve``.

Example::

    with EnhancerClient("127.0.0.1:50051") as client:
        session = client.start_session(references)          # stream.Views of the recorded frames
        for frames in ticks:                                 # stream.Views of one tick's renders
            images = client.enhance(session, frames)         # (M, H, W, 3) uint8
        client.close_session(session)

Against a server with TLS and a token (see :mod:`setdiff_bench.serve.security`)::

    EnhancerClient("sim-gpu-3:50051", tls_ca="ca.pem", token=ClientToken(file="token"))  # or the env variable
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from types import TracebackType

import grpc
import numpy as np
import torch
from grpc_health.v1 import health_pb2, health_pb2_grpc

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.stream import Views
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve import enhancer_pb2_grpc as pb_grpc
from setdiff_bench.serve.security import TOKEN_ENV, TokenSource, read_pem, token_source
from setdiff_bench.serve.server import MAX_MESSAGE_BYTES
from setdiff_bench.serve.wire import from_array, to_view


def _hwc(tensor: torch.Tensor) -> np.ndarray:
    return tensor.permute(1, 2, 0).contiguous().numpy()


def view_messages(views: Views) -> list[pb.View]:
    """:class:`~setdiff_bench.evaluation.stream.Views` → view messages (uint8 images stay bytes)."""
    names = list(views.names or (f"view{i}" for i in range(len(views.cameras))))
    messages = []
    for i, camera in enumerate(views.cameras):
        image = views.images[i]
        rgb = _hwc(image) if image.dtype == torch.uint8 else _hwc(image.float())
        cmap = None if views.cmaps is None else _hwc(views.cmaps[i].float())
        alpha = None if views.alphas is None or views.cmaps is None else _hwc(views.alphas[i].float())
        messages.append(to_view(names[i], rgb, camera, cmap, alpha))
    return messages


class EnhancerClient:
    """Blocking client; ``timeout`` (seconds) bounds every call.

    Args:
        address: ``host:port`` of the server.
        tls_ca: PEM file of the CA that signed the server's certificate: the channel is then TLS
            (plaintext without it).
        client_cert, client_key: PEM files of this client's certificate and key (mutual TLS).
        server_name: the name the server certificate must carry, when ``address`` uses another
            (e.g. an IP the certificate does not list).
        token: the bearer token sent with every call (a :class:`TokenSource`: a file, re-read when it
            changes, or an environment variable); ``None``: none sent.
    """

    def __init__(
        self,
        address: str,
        *,
        timeout: float = 60.0,
        tls_ca: str | os.PathLike[str] | None = None,
        client_cert: str | os.PathLike[str] | None = None,
        client_key: str | os.PathLike[str] | None = None,
        server_name: str | None = None,
        token: TokenSource | None = None,
    ) -> None:
        options = [
            ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
            ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
        ]
        if (client_cert is None) != (client_key is None):
            raise UsageError("give both --client-cert and --client-key", "--client-cert")
        if tls_ca is None and client_cert is not None:
            raise UsageError("a client certificate needs a TLS channel: give --tls-ca too", "--client-cert")
        if tls_ca is None:
            self.channel = grpc.insecure_channel(address, options=options)
        else:
            credentials = grpc.ssl_channel_credentials(
                root_certificates=read_pem(tls_ca, "--tls-ca", "CERTIFICATE"),
                private_key=None
                if client_key is None
                else read_pem(client_key, "--client-key", "PRIVATE KEY"),
                certificate_chain=None
                if client_cert is None
                else read_pem(client_cert, "--client-cert", "CERTIFICATE"),
            )
            if server_name:
                options.append(("grpc.ssl_target_name_override", server_name))
            self.channel = grpc.secure_channel(address, credentials, options=options)
        self.token = token
        self.stub = pb_grpc.EnhancerStub(self.channel)
        self.timeout = timeout

    @property
    def metadata(self) -> tuple[tuple[str, str], ...]:
        """Call metadata: the bearer token when one is set (read afresh, so a rotated file is followed)."""
        return () if self.token is None else (("authorization", f"Bearer {self.token.current()}"),)

    def __enter__(self) -> EnhancerClient:
        return self

    def __exit__(
        self, kind: type[BaseException] | None, error: BaseException | None, trace: TracebackType | None
    ) -> None:
        self.close()

    def close(self) -> None:
        self.channel.close()

    def wait_ready(self, timeout: float = 30.0) -> None:
        grpc.channel_ready_future(self.channel).result(timeout=timeout)

    def healthy(self) -> bool:
        reply = health_pb2_grpc.HealthStub(self.channel).Check(
            health_pb2.HealthCheckRequest(service=""), timeout=self.timeout
        )
        return reply.status == health_pb2.HealthCheckResponse.SERVING

    def start_session(
        self, references: Views, *, max_references: int = 0, ply_path: str = "", idle_timeout_s: float = 0.0
    ) -> str:
        """Open a session; ``idle_timeout_s`` asks for a lease shorter than the server's (0: the server's)."""
        reply = self.stub.start_session(
            pb.StartSessionRequest(
                references=view_messages(references),
                max_references=max_references,
                ply_path=ply_path,
                idle_timeout_s=idle_timeout_s,
            ),
            timeout=self.timeout,
            metadata=self.metadata,
        )
        return reply.session_uuid

    def enhance_request(self, session: str, frames: Views) -> pb.EnhanceRequest:
        return pb.EnhanceRequest(session_uuid=session, frames=view_messages(frames))

    def enhance(self, session: str, frames: Views | pb.EnhanceRequest) -> np.ndarray:
        """One tick → ``(M, H, W, 3)`` uint8 enhanced images, frame order."""
        request = frames if isinstance(frames, pb.EnhanceRequest) else self.enhance_request(session, frames)
        reply = self.stub.enhance(request, timeout=self.timeout, metadata=self.metadata)
        return np.stack([from_array(a, "reply", 3) for a in reply.images])

    def close_session(self, session: str) -> None:
        self.stub.close_session(
            pb.SessionId(session_uuid=session), timeout=self.timeout, metadata=self.metadata
        )

    def get_version(self) -> pb.VersionId:
        return self.stub.get_version(pb.Empty(), timeout=self.timeout, metadata=self.metadata)


def add_client_arguments(parser: argparse.ArgumentParser) -> None:
    """The connection options a client command takes (the server's TLS / token options, client side)."""
    parser.add_argument("--address", default="127.0.0.1:50051", help="host:port of the server")
    parser.add_argument(
        "--tls-ca", type=Path, default=None, help="PEM of the CA that signed the server certificate (TLS)"
    )
    parser.add_argument("--client-cert", type=Path, default=None, help="PEM client certificate (mutual TLS)")
    parser.add_argument("--client-key", type=Path, default=None, help="PEM client key (mutual TLS)")
    parser.add_argument(
        "--server-name", default=None, help="name in the server certificate, if not the address's host"
    )
    parser.add_argument(
        "--token-file",
        type=Path,
        default=None,
        help=f"file holding the bearer token (default: ${TOKEN_ENV} if set; never on the command line)",
    )


def client_from_arguments(args: argparse.Namespace, *, timeout: float = 60.0) -> EnhancerClient:
    """An :class:`EnhancerClient` from :func:`add_client_arguments`' options.

    Raises:
        UsageError: a missing or malformed certificate, key or token (one line naming it).
    """
    return EnhancerClient(
        args.address,
        timeout=timeout,
        tls_ca=args.tls_ca,
        client_cert=args.client_cert,
        client_key=args.client_key,
        server_name=args.server_name,
        token=token_source(args.token_file),
    )
