"""The sensorsim service's two roles: :class:`RendererService` (render fitted scenes, optionally enhanced) and
:class:`ProxyService` (forward to an upstream renderer, enhance what it returns).

Both answer a batch camera by camera, as AlpaSim's runtime requires: every requested ``camera_name`` exactly
once, in the request's order, with ``success`` and, when it failed, a one-line ``error_message`` (unknown scene,
zero or too large a resolution, an f-theta camera, a format other than PNG/JPEG, an ego mask asked for, an
upstream renderer that failed or did not answer within ``upstream_timeout``, a reply that would pass 64 MiB).
A camera's failure never fails its neighbours nor the server.  ``render_rgb`` answers the same failures as a
status: ``INVALID_ARGUMENT`` for the request, ``UNAVAILABLE`` for the upstream renderer.

The cameras of one batch that share a scene and a size are enhanced as one set (the stream session's tick).

Every reply carries a ``server-timing`` trailing metadata entry (the HTTP Server-Timing syntax): milliseconds
spent getting the frames (``frames``: the 3DGS render, or the upstream call, decoding and C-map render of
the proxy), enhancing them (``enhance``, absent without an enhancer) and encoding the reply (``encode``),
e.g. ``frames;dur=301.2, enhance;dur=15022.7, encode;dur=12.0``.  A client reads it with
``stub.batch_render_rgb.with_call(request)``; AlpaSim ignores it.
"""

from __future__ import annotations

import abc
import collections
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import grpc
import numpy as np

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.evaluation.stream import StreamInputError
from setdiff_bench.io.images import quantize_uint8
from setdiff_bench.serve.rpc_errors import LOG, Refusal, rpc
from setdiff_bench.serve.sensorsim import common_pb2 as common
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb
from setdiff_bench.serve.sensorsim import sensorsim_pb2_grpc as pb_grpc
from setdiff_bench.serve.sensorsim.enhancing import Frame, SceneSessions
from setdiff_bench.serve.sensorsim.imaging import check_format, decode, encode
from setdiff_bench.serve.sensorsim.lens import camera_spec, lens_camera, pose_message, render_lens
from setdiff_bench.serve.sensorsim.scenes import FittedScene, SceneLibrary
from setdiff_bench.serve.sensorsim.settings import MAX_MESSAGE_BYTES, SensorsimSettings
from setdiff_bench.version import __version__

#: Bytes a batch reply keeps free for its framing (camera names, flags, messages).
REPLY_MARGIN_BYTES = 1 << 20


class CameraFailure(Exception):
    """One camera of a batch failed: ``message`` is its ``error_message``; ``upstream`` when the upstream
    renderer (not the request) is at fault."""

    def __init__(self, message: str, *, upstream: bool = False) -> None:
        super().__init__(message)
        self.message = " ".join(message.split())
        self.upstream = upstream


@dataclass
class Pending:
    """A camera of a batch on its way: its request, parsed camera and scene, then its frame."""

    name: str
    request: pb.RGBRenderRequest
    scene: FittedScene | None = None
    frame: Frame | None = None
    failure: CameraFailure | None = None


def _failure(error: Exception, name: str) -> CameraFailure:
    """One line for any error of one camera (a toolkit error as it reads; anything else an incident)."""
    if isinstance(error, CameraFailure):
        return error
    if isinstance(error, SetDiffBenchError):
        return CameraFailure(error.one_line())
    incident = uuid.uuid4().hex[:12]
    LOG.error("incident %s: unexpected error rendering camera %r", incident, name, exc_info=error)
    return CameraFailure(f"internal server error (incident {incident}; details in the server log)")


def _report_timing(context: grpc.ServicerContext, timing: dict[str, float]) -> None:
    """Send ``timing`` (stage -> ms) as the reply's ``server-timing`` trailing metadata."""
    value = ", ".join(f"{stage};dur={ms:.1f}" for stage, ms in timing.items())
    context.set_trailing_metadata((("server-timing", value),))


def parse_server_timing(metadata: Sequence[tuple[str, Any]] | None) -> dict[str, float]:
    """Stage -> ms from a reply's trailing metadata (what :func:`_report_timing` sent; empty without it)."""
    for key, value in metadata or ():
        if key == "server-timing":
            stages = {}
            for entry in str(value).split(","):
                name, _, duration = entry.strip().partition(";dur=")
                if name and duration:
                    stages[name] = float(duration)
            return stages
    return {}


class SensorsimBase(pb_grpc.SensorsimServiceServicer, abc.ABC):
    """What both roles share: batch bookkeeping, enhancement, encoding, the reply budget."""

    role = "renderer"

    def __init__(
        self, settings: SensorsimSettings, enhancer: Any | None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        if settings.scenes is None:
            raise StreamInputError("the sensorsim service needs a folder of fitted scenes", "--scenes")
        self.settings = settings
        self.enhancer = enhancer
        self.library = SceneLibrary(settings.scenes, settings.max_loaded_scenes)
        self.enhancement = None if enhancer is None else SceneSessions(enhancer, settings.serve, clock)
        self._sessions_lock = (
            threading.Lock() if self.enhancement is None else self.enhancement._sessions_lock
        )
        self.internal_errors = 0

    # -------------------------------------------------------------------- the reaper's interface
    @property
    def sessions(self) -> dict[str, Any]:
        return {} if self.enhancement is None else self.enhancement.sessions

    def expire_idle(self, now: float | None = None) -> int:
        return 0 if self.enhancement is None else self.enhancement.expire_idle(now)

    # -------------------------------------------------------------------- one batch
    def _check(self, pending: Pending) -> None:
        """Everything about one camera that can be refused before any rendering (raises)."""
        request = pending.request
        check_format(request.image_format, request.image_quality, pending.name)
        pending.scene = self.library.get(request.scene_id)
        lens = lens_camera(request, pending.name)
        pending.frame = Frame(pending.name, np.zeros((0, 0, 3), np.uint8), lens)

    @abc.abstractmethod
    def _frames(self, batch: list[Pending]) -> None:
        """Fill each live camera's ``frame`` with its image, or its ``failure`` (role specific)."""

    def _run(
        self, items: Sequence[tuple[str, pb.RGBRenderRequest]], timing: dict[str, float]
    ) -> list[Pending]:
        """The batch's cameras with their frames or failures; ``timing`` receives the milliseconds of each
        stage (``frames``, ``enhance``)."""
        batch = [Pending(name, request) for name, request in items]
        seen: set[str] = set()
        for pending in batch:
            try:
                if pending.name in seen:
                    raise CameraFailure(f"camera_name {pending.name!r} appears more than once in the batch")
                seen.add(pending.name)
                self._check(pending)
            except Exception as error:  # each camera answers for itself
                pending.failure = _failure(error, pending.name)
        start = time.perf_counter()
        self._frames([p for p in batch if p.failure is None])
        timing["frames"] = (time.perf_counter() - start) * 1e3
        if self.enhancement is not None:
            start = time.perf_counter()
            self._enhance([p for p in batch if p.failure is None])
            timing["enhance"] = (time.perf_counter() - start) * 1e3
        return batch

    def _enhance(self, batch: list[Pending]) -> None:
        """Enhance the batch's frames, one set per scene and size."""
        groups: dict[tuple[str, int, int], list[Pending]] = collections.defaultdict(list)
        for pending in batch:
            assert pending.scene is not None and pending.frame is not None
            height, width = pending.frame.rgb.shape[:2]
            groups[pending.scene.scene_id, height, width].append(pending)
        assert self.enhancement is not None
        for group in groups.values():
            try:
                images = self.enhancement.enhance(group[0].scene, [p.frame for p in group])
            except Exception as error:
                failure = _failure(error, ", ".join(p.name for p in group))
                for pending in group:
                    pending.failure = failure
                continue
            for pending, image in zip(group, images, strict=True):
                pending.frame = Frame(pending.name, image, pending.frame.camera)

    def _encode(self, pending: Pending, budget: int) -> bytes:
        request = pending.request
        data = encode(pending.frame.rgb, request.image_format, request.image_quality)
        if len(data) > budget:
            raise CameraFailure(
                f"the reply would pass {MAX_MESSAGE_BYTES // 2**20} MiB with this camera's "
                f"{len(data) / 2**20:.1f} MiB image; ask for fewer cameras per batch, JPEG or a smaller size"
            )
        return data

    # -------------------------------------------------------------------- RPCs
    @rpc
    def batch_render_rgb(
        self, request: pb.BatchRGBRenderRequest, context: grpc.ServicerContext
    ) -> pb.BatchRGBRenderReturn:
        timing: dict[str, float] = {}
        batch = self._run([(item.camera_name, item.request) for item in request.items], timing)
        start = time.perf_counter()
        reply = pb.BatchRGBRenderReturn()
        budget = MAX_MESSAGE_BYTES - REPLY_MARGIN_BYTES
        for pending in batch:
            item = reply.items.add(camera_name=pending.name)
            if pending.failure is None:
                try:
                    data = self._encode(pending, budget)
                    budget -= len(data)
                    item.result.image_bytes = data
                    item.success = True
                    continue
                except Exception as error:
                    pending.failure = _failure(error, pending.name)
            item.success = False
            item.error_message = pending.failure.message
        timing["encode"] = (time.perf_counter() - start) * 1e3
        _report_timing(context, timing)
        return reply

    @rpc
    def render_rgb(self, request: pb.RGBRenderRequest, context: grpc.ServicerContext) -> pb.RGBRenderReturn:
        timing: dict[str, float] = {}
        [pending] = self._run([(request.camera_intrinsics.logical_id or "camera", request)], timing)
        if pending.failure is None:
            try:
                start = time.perf_counter()
                data = self._encode(pending, MAX_MESSAGE_BYTES - REPLY_MARGIN_BYTES)
                timing["encode"] = (time.perf_counter() - start) * 1e3
                _report_timing(context, timing)
                return pb.RGBRenderReturn(image_bytes=data)
            except Exception as error:
                pending.failure = _failure(error, pending.name)
        code = grpc.StatusCode.UNAVAILABLE if pending.failure.upstream else grpc.StatusCode.INVALID_ARGUMENT
        raise Refusal(code, pending.failure.message)

    def _enhancer_words(self) -> str:
        if self.enhancer is None:
            return ""
        name = getattr(self.enhancer, "name", "enhancer")
        return f" + {name} {getattr(self.enhancer, 'checkpoint', '')}".rstrip()


class RendererService(SensorsimBase):
    """Render the fitted scenes of a folder (3DGS), enhanced in place when an enhancer is given."""

    def _check(self, pending: Pending) -> None:
        if pending.request.insert_ego_mask:
            raise StreamInputError(
                "ego masks are not served (get_available_ego_masks lists none)", pending.name
            )
        super()._check(pending)

    def _frames(self, batch: list[Pending]) -> None:
        with_geometry = self.enhancement is not None
        for pending in batch:
            try:
                assert pending.scene is not None and pending.frame is not None
                drawn = render_lens(
                    pending.scene.gaussians, [pending.frame.camera], with_geometry=with_geometry
                )
                rgb = quantize_uint8(drawn.rgb[0].permute(1, 2, 0).numpy())
                pending.frame = Frame(
                    pending.name,
                    rgb,
                    pending.frame.camera,
                    None if drawn.cmap is None else drawn.cmap[0],
                    None if drawn.alpha is None else drawn.alpha[0],
                )
            except Exception as error:
                pending.failure = _failure(error, pending.name)

    @rpc
    def get_version(self, request: common.Empty, context: grpc.ServicerContext) -> common.VersionId:
        return common.VersionId(
            version_id=f"setdiff-bench {__version__} 3dgs renderer{self._enhancer_words()}"
        )

    @rpc
    def get_available_scenes(
        self, request: common.Empty, context: grpc.ServicerContext
    ) -> common.AvailableScenesReturn:
        return common.AvailableScenesReturn(scene_ids=self.library.scene_ids())

    @rpc
    def get_available_cameras(
        self, request: pb.AvailableCamerasRequest, context: grpc.ServicerContext
    ) -> pb.AvailableCamerasReturn:
        scene = self.library.get(request.scene_id)
        return pb.AvailableCamerasReturn(
            available_cameras=[
                pb.AvailableCamerasReturn.AvailableCamera(
                    intrinsics=camera_spec(camera.camera, camera.logical_id),
                    rig_to_camera=pose_message(camera.camera_to_rig),
                    logical_id=camera.logical_id,
                )
                for camera in scene.cameras
            ]
        )

    @rpc
    def get_available_ego_masks(
        self, request: common.Empty, context: grpc.ServicerContext
    ) -> pb.AvailableEgoMasksReturn:
        return pb.AvailableEgoMasksReturn()


class ProxyService(SensorsimBase):
    """Forward every call to ``settings.upstream``; enhance the images it returns (C-maps from the scene's PLY)."""

    role = "proxy"

    def __init__(
        self, settings: SensorsimSettings, enhancer: Any, clock: Callable[[], float] = time.monotonic
    ) -> None:
        if settings.upstream is None:
            raise StreamInputError("the proxy needs an upstream renderer (HOST:PORT)", "--upstream")
        super().__init__(settings, enhancer, clock)
        self.channel = grpc.insecure_channel(
            settings.upstream,
            options=[
                ("grpc.max_receive_message_length", MAX_MESSAGE_BYTES),
                ("grpc.max_send_message_length", MAX_MESSAGE_BYTES),
            ],
        )
        self.upstream = pb_grpc.SensorsimServiceStub(self.channel)

    def close(self) -> None:
        self.channel.close()

    def _upstream_problem(self, error: grpc.RpcError) -> str:
        code = error.code() if hasattr(error, "code") else None
        if code == grpc.StatusCode.DEADLINE_EXCEEDED:
            return (
                f"upstream renderer {self.settings.upstream} did not answer within "
                f"{self.settings.upstream_timeout:g} s"
            )
        details = error.details() if hasattr(error, "details") else str(error)
        name = code.name if code is not None else "error"
        return f"upstream renderer {self.settings.upstream} failed: {name}: {' '.join(str(details).split())}"

    def _forward(self, method: str, request: Any) -> Any:
        try:
            return getattr(self.upstream, method)(request, timeout=self.settings.upstream_timeout)
        except grpc.RpcError as error:
            raise Refusal(grpc.StatusCode.UNAVAILABLE, self._upstream_problem(error)) from None

    def _frames(self, batch: list[Pending]) -> None:
        if not batch:
            return
        forwarded = pb.BatchRGBRenderRequest()
        for pending in batch:
            item = forwarded.items.add(camera_name=pending.name)
            item.request.CopyFrom(pending.request)
            if self.settings.upstream_png:
                item.request.image_format = pb.ImageFormat.PNG
        try:
            reply = self.upstream.batch_render_rgb(forwarded, timeout=self.settings.upstream_timeout)
        except grpc.RpcError as error:
            failure = CameraFailure(self._upstream_problem(error), upstream=True)
            for pending in batch:
                pending.failure = failure
            return
        answers = {item.camera_name: item for item in reply.items}
        for pending in batch:
            answer = answers.get(pending.name)
            try:
                if answer is None:
                    raise CameraFailure(
                        f"upstream renderer {self.settings.upstream} did not answer this camera",
                        upstream=True,
                    )
                if not answer.success:
                    raise CameraFailure(
                        f"upstream renderer {self.settings.upstream}: {answer.error_message or 'failed'}",
                        upstream=True,
                    )
                assert pending.frame is not None
                camera = pending.frame.camera.camera
                rgb = decode(answer.result.image_bytes, camera.height, camera.width, pending.name)
                pending.frame = Frame(pending.name, rgb, pending.frame.camera)
            except Exception as error:
                pending.failure = _failure(error, pending.name)

    @rpc
    def get_version(self, request: common.Empty, context: grpc.ServicerContext) -> common.VersionId:
        version = self._forward("get_version", request)
        version.version_id = (
            f"{version.version_id} + setdiff-bench {__version__} proxy{self._enhancer_words()}"
        )
        return version

    @rpc
    def get_available_scenes(
        self, request: common.Empty, context: grpc.ServicerContext
    ) -> common.AvailableScenesReturn:
        return self._forward("get_available_scenes", request)

    @rpc
    def get_available_cameras(
        self, request: pb.AvailableCamerasRequest, context: grpc.ServicerContext
    ) -> pb.AvailableCamerasReturn:
        return self._forward("get_available_cameras", request)

    @rpc
    def get_available_ego_masks(
        self, request: common.Empty, context: grpc.ServicerContext
    ) -> pb.AvailableEgoMasksReturn:
        return self._forward("get_available_ego_masks", request)
