"""A small Python client of ``setdiff-bench serve``.

Example::

    with EnhancerClient("127.0.0.1:50051") as client:
        session = client.start_session(references)          # stream.Views of the recorded frames
        for frames in ticks:                                 # stream.Views of one tick's renders
            images = client.enhance(session, frames)         # (M, H, W, 3) uint8
        client.close_session(session)
"""

from __future__ import annotations

from types import TracebackType

import grpc
import numpy as np
import torch
from grpc_health.v1 import health_pb2, health_pb2_grpc

from setdiff_bench.evaluation.stream import Views
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve import enhancer_pb2_grpc as pb_grpc
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
    """Blocking client; ``timeout`` (seconds) bounds every call."""

    def __init__(self, address: str, *, timeout: float = 60.0) -> None:
        self.channel = grpc.insecure_channel(
            address,
            options=[
                ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
                ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
            ],
        )
        self.stub = pb_grpc.EnhancerStub(self.channel)
        self.timeout = timeout

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

    def start_session(self, references: Views, *, max_references: int = 0, ply_path: str = "") -> str:
        reply = self.stub.start_session(
            pb.StartSessionRequest(
                references=view_messages(references), max_references=max_references, ply_path=ply_path
            ),
            timeout=self.timeout,
        )
        return reply.session_uuid

    def enhance_request(self, session: str, frames: Views) -> pb.EnhanceRequest:
        return pb.EnhanceRequest(session_uuid=session, frames=view_messages(frames))

    def enhance(self, session: str, frames: Views | pb.EnhanceRequest) -> np.ndarray:
        """One tick → ``(M, H, W, 3)`` uint8 enhanced images, frame order."""
        request = frames if isinstance(frames, pb.EnhanceRequest) else self.enhance_request(session, frames)
        reply = self.stub.enhance(request, timeout=self.timeout)
        return np.stack([from_array(a, "reply", 3) for a in reply.images])

    def close_session(self, session: str) -> None:
        self.stub.close_session(pb.SessionId(session_uuid=session), timeout=self.timeout)

    def get_version(self) -> pb.VersionId:
        return self.stub.get_version(pb.Empty(), timeout=self.timeout)
