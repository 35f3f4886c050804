"""The sensorsim service (AlpaSim's renderer protocol) with real servers on free 127.0.0.1 ports, driven by a
client built from our ``sensorsim.proto`` that calls what AlpaSim's runtime calls, in its order, with JPEG q95:
the renderer alone, the proxy in front of it (PNG bytes equal to ``run``'s for the same views and C-maps), a
fisheye camera, an upstream that dies or hangs mid-rollout, malformed requests answered per camera, the
wire format against AlpaSim's field numbers, the token and the bind rule."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from concurrent import futures
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import cv2
import grpc
import numpy as np
import pytest
import torch
from google.protobuf import descriptor_pb2

from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.stream import Views
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.images import quantize_uint8, read_rgb
from setdiff_bench.io.run_layout import IMAGES_DIR
from setdiff_bench.rotations import quaternion_to_matrix
from setdiff_bench.serve.security import ServerTls, TokenSource
from setdiff_bench.serve.sensorsim import common_pb2 as common
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb
from setdiff_bench.serve.sensorsim import sensorsim_pb2_grpc as pb_grpc
from setdiff_bench.serve.sensorsim.server import RunningSensorsim, start_sensorsim
from setdiff_bench.serve.sensorsim.service import parse_server_timing
from setdiff_bench.serve.sensorsim.settings import SensorsimSettings
from setdiff_bench.serve.settings import ServeSettings
from tests.evaluation.stream.stream_fixtures import run_batch
from tests.serve.sensorsim_fixtures import (
    CAMERAS,
    SCENE_ID,
    batch_request,
    decoded,
    make_scene,
    render_request,
    start_rollout,
    stub,
    tick_cameras,
    write_tick_packet,
)
from tests.serve.serve_fixtures import Certificates

#: Small frames (48×32): the domain warning is expected.
pytestmark = pytest.mark.filterwarnings("ignore::setdiff_bench.errors.OutOfDistributionWarning")
ROOT = Path(__file__).resolve().parents[2]
NAMES = [name for name, _ in CAMERAS]


@pytest.fixture(scope="module")
def scenes(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("scenes")
    make_scene(root)
    return root


@pytest.fixture(scope="module")
def enhancer(checkpoint: Path) -> Any:
    """The tests' tiny random SetDiff (conftest; the shipped tiny_setdiff takes ~20 s to load here)."""
    return load_enhancer("setdiff", str(checkpoint), device="cpu")


@contextmanager
def running(scenes: Path, enhancer: Any = None, **options: Any) -> Iterator[RunningSensorsim]:
    serve = ServeSettings(port=0, **options.pop("serve", {}))
    server = start_sensorsim(SensorsimSettings(serve=serve, scenes=scenes, **options), enhancer)
    try:
        yield server
    finally:
        server.stop(grace=1)


@pytest.fixture(scope="module")
def renderer(scenes: Path) -> Iterator[RunningSensorsim]:
    with running(scenes) as server:
        yield server


@pytest.fixture(scope="module")
def proxy(scenes: Path, enhancer: Any, renderer: RunningSensorsim) -> Iterator[RunningSensorsim]:
    with running(scenes, enhancer, role="proxy", upstream=f"127.0.0.1:{renderer.port}") as server:
        yield server


def wire_camera(request: pb.RGBRenderRequest) -> Camera:
    """The camera a request carries, read back from its float32 wire values with the project's rotations."""
    sent = pb.RGBRenderRequest.FromString(request.SerializeToString())
    q, v = sent.sensor_pose.start_pose.quat, sent.sensor_pose.start_pose.vec
    c2w = np.eye(4)
    c2w[:3, :3] = quaternion_to_matrix([q.w, q.x, q.y, q.z], order="wxyz")
    c2w[:3, 3] = [v.x, v.y, v.z]
    p = sent.camera_intrinsics.opencv_pinhole_param
    K = np.array(
        [[p.focal_length_x, 0, p.principal_point_x + 0.5], [0, p.focal_length_y, p.principal_point_y + 0.5]]
    )
    return Camera.from_c2w(c2w, np.vstack([K, [0, 0, 1]]), sent.resolution_w, sent.resolution_h)


# ---------------------------------------------------------------------------------------------- the wire format
def test_generated_code_matches_the_protos(tmp_path: Path) -> None:
    protoc = pytest.importorskip("grpc_tools.protoc")
    for name, module in (("common", common), ("sensorsim", pb)):
        out = tmp_path / f"{name}.desc"
        path = f"setdiff_bench/serve/sensorsim/{name}.proto"
        assert protoc.main(["protoc", f"-I{ROOT}", f"--descriptor_set_out={out}", path]) == 0
        compiled = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes()).file[0]
        for message in compiled.message_type:  # protoc's --python_out drops the derived json_name
            for field in message.field:
                field.ClearField("json_name")
            for nested in message.nested_type:
                for field in nested.field:
                    field.ClearField("json_name")
        assert compiled == descriptor_pb2.FileDescriptorProto.FromString(module.DESCRIPTOR.serialized_pb)


#: Field numbers and types of AlpaSim's sensorsim.proto / common.proto (read from NVlabs/alpasim by hand).
ALPASIM_FIELDS = {
    "RGBRenderRequest": [
        ("scene_id", 1, "string"), ("resolution_h", 2, "uint32"), ("resolution_w", 3, "uint32"),
        ("camera_intrinsics", 4, "message"), ("frame_start_us", 5, "fixed64"), ("frame_end_us", 6, "fixed64"),
        ("sensor_pose", 7, "message"), ("dynamic_objects", 8, "message"), ("image_format", 9, "enum"),
        ("image_quality", 10, "float"), ("insert_ego_mask", 11, "bool"), ("ego_mask_id", 12, "message"),
    ],
    "CameraSpec": [
        ("ftheta_param", 2, "message"), ("opencv_pinhole_param", 3, "message"),
        ("opencv_fisheye_param", 4, "message"), ("logical_id", 5, "string"), ("resolution_h", 7, "uint32"),
        ("resolution_w", 8, "uint32"), ("shutter_type", 9, "enum"), ("bivariate_windshield_model_param", 10, "message"),
    ],
    "OpenCVFisheyeCameraParam": [
        ("principal_point_x", 1, "double"), ("focal_length_x", 3, "double"), ("radial_coeffs", 5, "double"),
        ("max_angle", 6, "double"),
    ],
    "BatchRGBRenderRequestItem": [("camera_name", 1, "string"), ("request", 2, "message")],
    "BatchRGBRenderReturnItem": [
        ("camera_name", 1, "string"), ("result", 2, "message"), ("success", 3, "bool"), ("error_message", 4, "string"),
    ],
    "AvailableCamerasReturn.AvailableCamera": [
        ("intrinsics", 1, "message"), ("rig_to_camera", 2, "message"), ("logical_id", 3, "string"),
    ],
}  # fmt: skip


def test_the_wire_format_is_alpasims() -> None:
    types = {v: k[len("TYPE_") :].lower() for k, v in descriptor_pb2.FieldDescriptorProto.Type.items()}
    for path, fields in ALPASIM_FIELDS.items():
        message = pb.DESCRIPTOR.message_types_by_name[path.split(".")[0]]
        for nested in path.split(".")[1:]:
            message = message.nested_types_by_name[nested]
        for name, number, kind in fields:
            assert (message.fields_by_name[name].number, types[message.fields_by_name[name].type]) == (
                number,
                kind,
            )
    quat = common.DESCRIPTOR.message_types_by_name["Quat"]
    assert [(f.name, f.number) for f in quat.fields] == [("w", 1), ("x", 2), ("y", 3), ("z", 4)]
    assert (pb.ImageFormat.PNG, pb.ImageFormat.JPEG) == (1, 2)
    service = pb.DESCRIPTOR.services_by_name["SensorsimService"]
    assert service.full_name == "nre.grpc.protos.sensorsim.SensorsimService"
    assert service.methods_by_name["get_version"].input_type.full_name == "common.Empty"


# ---------------------------------------------------------------------------------------------- the renderer
def test_renderer_alone_answers_alpasims_calls(renderer: RunningSensorsim, scenes: Path) -> None:
    client = stub(f"127.0.0.1:{renderer.port}")
    assert start_rollout(client) == ["camera"]
    cameras = client.get_available_cameras(pb.AvailableCamerasRequest(scene_id=SCENE_ID), timeout=30)
    [camera] = cameras.available_cameras
    pinhole = camera.intrinsics.opencv_pinhole_param
    assert pinhole.focal_length_x == pytest.approx(0.8 * 48)  # rig_camera: focal 0.8 W, centre W / 2
    assert (pinhole.principal_point_x, camera.intrinsics.resolution_w) == (23.5, 48)
    q = camera.rig_to_camera.quat  # camera axes in the rig (x forward, y left, z up): optical axis = rig x
    assert quaternion_to_matrix([q.w, q.x, q.y, q.z], order="wxyz")[:, 2] == pytest.approx(
        [1, 0, 0], abs=1e-6
    )
    gaussians = read_ply(scenes / SCENE_ID / "scene.ply")
    for tick in range(2):
        request = batch_request(tick)
        images = decoded(client.batch_render_rgb(request, timeout=60), NAMES)
        for item in request.items:
            with torch.no_grad():
                drawn = render(gaussians, [wire_camera(item.request)], with_geometry=False).rgb[0]
            expected = quantize_uint8(drawn.clamp(0, 1).permute(1, 2, 0).numpy()).astype(int)
            assert images[item.camera_name].shape == (32, 48, 3)
            assert np.abs(images[item.camera_name].astype(int) - expected).mean() < 4  # JPEG q95
            png = render_request(wire_camera(item.request), item.camera_name, tick, pb.ImageFormat.PNG)
            png.CopyFrom(item.request)
            png.image_format = pb.ImageFormat.PNG
            data = client.render_rgb(png, timeout=60).image_bytes
            exact = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]
            assert np.array_equal(exact, expected)  # PNG: the render itself


def test_fisheye_is_the_equidistant_projection_and_ftheta_is_refused(renderer: RunningSensorsim) -> None:
    client = stub(f"127.0.0.1:{renderer.port}")
    wide = tick_cameras(0, size=(64, 96))[0]
    f = 32.0  # a wide lens: 96 px span 113 degrees on the pinhole, 143 on the fisheye
    pinhole = render_request(wide, "wide", 0, pb.ImageFormat.PNG)
    pinhole.camera_intrinsics.opencv_pinhole_param.focal_length_x = f
    pinhole.camera_intrinsics.opencv_pinhole_param.focal_length_y = f
    fisheye = pb.RGBRenderRequest()
    fisheye.CopyFrom(pinhole)
    fisheye.camera_intrinsics.opencv_fisheye_param.CopyFrom(
        pb.OpenCVFisheyeCameraParam(
            principal_point_x=47.5, principal_point_y=31.5, focal_length_x=f, focal_length_y=f,
            radial_coeffs=[0.0] * 4, max_angle=1.3,
        )
    )  # fmt: skip
    ftheta = pb.RGBRenderRequest()
    ftheta.CopyFrom(pinhole)
    ftheta.camera_intrinsics.ftheta_param.principal_point_x = 47.5
    batch = pb.BatchRGBRenderRequest()
    for name, request in (("pinhole", pinhole), ("fisheye", fisheye), ("ftheta", ftheta)):
        batch.items.add(camera_name=name, request=request)
    reply = client.batch_render_rgb(batch, timeout=60)
    assert [(i.camera_name, i.success) for i in reply.items] == [
        (n, n != "ftheta") for n in ("pinhole", "fisheye", "ftheta")
    ]
    assert reply.items[2].error_message.startswith("ftheta: f-theta cameras are not served")
    flat, fish = (
        cv2.imdecode(np.frombuffer(i.result.image_bytes, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1].astype(
            float
        )
        for i in reply.items[:2]
    )
    # equidistant: column j is d = j - 47.5 px from the axis and sees the ray at angle d / f, which the pinhole
    # draws at column 47.5 + f tan(d / f); rays past max_angle (1.3 rad, d > 41.6 px) are black
    columns = np.arange(20, 76)
    d = columns - 47.5
    at = 47.5 + f * np.tan(d / f)
    expected = np.stack([np.interp(at, np.arange(96), flat[32, :, c]) for c in range(3)], axis=-1)
    error = np.abs(fish[32, columns] - expected).mean()
    assert error < 4
    assert np.abs(fish[32, columns] - flat[32, columns]).mean() > 4 * error  # not the pinhole image
    assert fish[32, :5].max() == 0 and fish[32, -5:].max() == 0  # beyond max_angle


# ---------------------------------------------------------------------------------------------- the proxy
def test_proxy_png_equals_run_for_the_same_views_and_cmaps(
    proxy: RunningSensorsim, scenes: Path, checkpoint: Path, tmp_path: Path
) -> None:
    client = stub(f"127.0.0.1:{proxy.port}")
    assert start_rollout(client) == ["camera"]
    assert "proxy" in client.get_version(common.Empty(), timeout=30).version_id
    gaussians = read_ply(scenes / SCENE_ID / "scene.ply")
    recorded = sorted((scenes / SCENE_ID / "images").glob("*.png"))
    replies = {}
    for tick in range(2):
        request = batch_request(tick, pb.ImageFormat.PNG)
        started = time.perf_counter()
        reply, call = client.batch_render_rgb.with_call(request, timeout=60)
        wall_ms = (time.perf_counter() - started) * 1e3
        decoded(reply, NAMES)
        stages = parse_server_timing(call.trailing_metadata())
        assert set(stages) == {"frames", "enhance", "encode"}
        assert all(ms > 0 for ms in stages.values()) and sum(stages.values()) < wall_ms
        replies[tick] = {item.camera_name: item.result.image_bytes for item in reply.items}
        cameras = [wire_camera(item.request) for item in request.items]
        with torch.no_grad():
            targets = render(gaussians, cameras)
        [session] = proxy.service.enhancement.sessions.values()
        chosen = session.stream.select(cameras)
        ref_cameras = [session.stream.references.cameras[i] for i in chosen]
        with torch.no_grad():
            refs = render(gaussians, ref_cameras)
        images = [np.rint(read_rgb(recorded[i]) * 255).astype(np.uint8) for i in chosen]
        references = Views(
            images=torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2),
            cameras=ref_cameras,
            cmaps=refs.cmap,
            alphas=refs.alpha,
            names=[f"rec{i}" for i in chosen],
        )
        frames = Views(
            images=torch.from_numpy(
                quantize_uint8(targets.rgb.clamp(0, 1).permute(0, 2, 3, 1).numpy())
            ).permute(0, 3, 1, 2),
            cameras=cameras,
            cmaps=targets.cmap,
            alphas=targets.alpha,
            names=[f"{name}/{tick:06d}.png" for name in NAMES],
        )
        write_tick_packet(tmp_path / "store", tick, references, frames)
    run_batch(tmp_path / "store", tmp_path / "run", checkpoint)
    for tick, images in replies.items():
        for name, data in images.items():
            [written] = (tmp_path / "run" / IMAGES_DIR).rglob(f"{name}/{tick:06d}.png")
            assert data == written.read_bytes(), (tick, name)


@contextmanager
def upstream_that_hangs(seconds: float) -> Iterator[int]:
    """A sensorsim server whose batch_render_rgb answers only after ``seconds``."""

    class Hanging(pb_grpc.SensorsimServiceServicer):
        def batch_render_rgb(self, request: Any, context: Any) -> pb.BatchRGBRenderReturn:
            time.sleep(seconds)
            return pb.BatchRGBRenderReturn()

    server = grpc.server(futures.ThreadPoolExecutor(max_workers=2))
    pb_grpc.add_SensorsimServiceServicer_to_server(Hanging(), server)
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        yield port
    finally:
        server.stop(0)


def test_an_upstream_that_dies_or_hangs_fails_its_cameras_not_the_rollout(
    scenes: Path, enhancer: Any
) -> None:
    with (
        running(scenes) as upstream,
        running(scenes, enhancer, role="proxy", upstream=f"127.0.0.1:{upstream.port}") as proxy,
    ):
        client = stub(f"127.0.0.1:{proxy.port}")
        start_rollout(client)
        decoded(client.batch_render_rgb(batch_request(0), timeout=60), NAMES)
        upstream.stop(grace=0)
        started = time.monotonic()
        reply = client.batch_render_rgb(batch_request(1), timeout=60)
        assert time.monotonic() - started < 10
        assert [item.camera_name for item in reply.items] == NAMES
        for item in reply.items:
            assert not item.success
            assert item.error_message.startswith(
                f"upstream renderer 127.0.0.1:{upstream.port} failed: UNAVAILABLE"
            )
        with pytest.raises(grpc.RpcError) as caught:
            client.get_available_scenes(common.Empty(), timeout=30)
        assert caught.value.code() == grpc.StatusCode.UNAVAILABLE
    with (
        upstream_that_hangs(5.0) as port,
        running(scenes, enhancer, role="proxy", upstream=f"127.0.0.1:{port}", upstream_timeout=0.5) as proxy,
    ):
        started = time.monotonic()
        reply = stub(f"127.0.0.1:{proxy.port}").batch_render_rgb(batch_request(0), timeout=60)
        assert time.monotonic() - started < 4
        assert {item.error_message for item in reply.items} == {
            f"upstream renderer 127.0.0.1:{port} did not answer within 0.5 s"
        }


# ---------------------------------------------------------------------------------------------- bad requests
def bad_batch() -> tuple[pb.BatchRGBRenderRequest, list[str]]:
    """A batch of one good camera and one of each malformed kind, with each camera's expected error ("": none)."""
    camera = tick_cameras(0)[0]
    batch = pb.BatchRGBRenderRequest()
    expected = []

    def add(name: str, error: str, **changes: Any) -> pb.RGBRenderRequest:
        request = render_request(camera, name, 0)
        for key, value in changes.items():
            setattr(request, key, value)
        batch.items.add(camera_name=name, request=request)
        expected.append(error)
        return batch.items[-1].request

    add("good", "")
    add("unknown_scene", "scene_id: unknown scene 'nowhere'; this server has 1: street", scene_id="nowhere")
    add("zero", "zero: resolution_h x resolution_w must be 1..4096 each, got 0x48", resolution_h=0)
    add("avc", "avc: image_format AVC is not served; ask for PNG or JPEG", image_format=pb.ImageFormat.AVC)
    add("quality", "quality: image_quality must be 0..100 for JPEG, got 250", image_quality=250)
    add("good", "camera_name 'good' appears more than once in the batch")
    broken = add("nan_pose", "nan_pose sensor_pose.start_pose: quaternion has NaN or infinite values")
    broken.sensor_pose.start_pose.quat.w = float("nan")
    return batch, expected


@pytest.mark.parametrize("role", ["renderer", "proxy"])
def test_malformed_requests_are_answered_per_camera_and_the_server_keeps_serving(
    role: str, renderer: RunningSensorsim, proxy: RunningSensorsim
) -> None:
    server = renderer if role == "renderer" else proxy
    client = stub(f"127.0.0.1:{server.port}")
    batch, expected = bad_batch()
    reply = client.batch_render_rgb(batch, timeout=60)
    assert [item.camera_name for item in reply.items] == [item.camera_name for item in batch.items]
    assert reply.items[0].success and reply.items[0].result.image_bytes[:2] == b"\xff\xd8"  # a JPEG
    assert [item.error_message for item in reply.items] == expected
    assert not any(item.success for item in reply.items[1:])
    with pytest.raises(grpc.RpcError) as caught:
        client.render_rgb(batch.items[1].request, timeout=30)
    assert caught.value.code() == grpc.StatusCode.INVALID_ARGUMENT
    assert caught.value.details() == expected[1]
    huge = batch_request(0)
    huge.items[0].request.dynamic_objects.add(track_id="x" * (70 * 2**20))  # 70 MiB: over AlpaSim's limit
    options = [("grpc.max_send_message_length", 2**28)]
    with (
        grpc.insecure_channel(f"127.0.0.1:{server.port}", options) as channel,
        pytest.raises(grpc.RpcError) as caught,
    ):
        pb_grpc.SensorsimServiceStub(channel).batch_render_rgb(huge, timeout=60)
    assert caught.value.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
    decoded(client.batch_render_rgb(batch_request(1), timeout=60), NAMES)  # still serving
    assert server.service.internal_errors == 0


# ---------------------------------------------------------------------------------------------- state and gates
def test_scene_sessions_are_shared_by_concurrent_rollouts_bounded_and_expired(
    scenes: Path, enhancer: Any
) -> None:
    now = [0.0]
    with (
        running(scenes) as upstream,
        running(
            scenes,
            enhancer,
            role="proxy",
            upstream=f"127.0.0.1:{upstream.port}",
            serve={"max_sessions": 1, "session_idle_timeout": 10.0, "workers": 8},
        ) as proxy,
    ):
        proxy.service.enhancement.clock = lambda: now[0]
        client = stub(f"127.0.0.1:{proxy.port}")
        alone = {tick: client.batch_render_rgb(batch_request(tick), timeout=60) for tick in range(3)}
        together: dict[tuple[int, int], Any] = {}

        def rollout(index: int) -> None:
            for tick in range(3):
                together[index, tick] = client.batch_render_rgb(batch_request(tick), timeout=60)

        threads = [threading.Thread(target=rollout, args=(i,)) for i in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        assert all(together[i, t] == alone[t] for i in range(4) for t in range(3))  # outputs do not mix
        sessions = proxy.service.enhancement
        assert list(sessions.sessions) == [f"{SCENE_ID}@32x48"] and sessions.opened == 1
        decoded(client.batch_render_rgb(batch_request(0, size=(24, 40)), timeout=60), NAMES)
        assert list(sessions.sessions) == [f"{SCENE_ID}@24x40"]  # max_sessions 1: the idle one made room
        now[0] = 11.0
        assert sessions.expire_idle() == 1 and not sessions.sessions


def test_token_tls_and_the_bind_rule_are_the_enhancer_servers(
    scenes: Path, tmp_path: Path, certificates: Certificates
) -> None:
    token_file = tmp_path / "token"
    token_file.write_text("s3cret-token-of-24-chars")
    tls = ServerTls.from_files(certificates.server_cert, certificates.server_key)
    with running(scenes, serve={"token": TokenSource(file=token_file), "tls": tls}) as server:
        credentials = grpc.ssl_channel_credentials(certificates.ca.read_bytes())
        client = pb_grpc.SensorsimServiceStub(grpc.secure_channel(f"localhost:{server.port}", credentials))
        with pytest.raises(grpc.RpcError) as caught:
            client.get_available_scenes(common.Empty(), timeout=30)
        assert caught.value.code() == grpc.StatusCode.UNAUTHENTICATED
        metadata = [("authorization", "Bearer s3cret-token-of-24-chars")]
        assert client.get_available_scenes(common.Empty(), timeout=30, metadata=metadata).scene_ids == [
            SCENE_ID
        ]
    with pytest.raises(UsageError, match=r"0\.0\.0\.0 is not a loopback address"):
        start_sensorsim(SensorsimSettings(ServeSettings(host="0.0.0.0", port=0), scenes=scenes))


def test_cli_builds_the_settings_and_refuses_in_one_line(scenes: Path) -> None:
    import argparse

    from setdiff_bench.cli import serve as cli

    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)

    def settings(*words: str) -> SensorsimSettings:
        return cli.sensorsim_settings_from_arguments(parser.parse_args(["--protocol", "sensorsim", *words]))

    made = settings(
        "--scenes", str(scenes), "--role", "proxy", "--upstream", "127.0.0.1:7", "--checkpoint", "c"
    )
    assert (made.role, made.upstream, made.scenes, made.upstream_png) == (
        "proxy",
        "127.0.0.1:7",
        scenes,
        True,
    )
    assert made.serve.host == "127.0.0.1" and settings("--scenes", str(scenes)).upstream is None
    for words, message in (
        ((), "--scenes: --protocol sensorsim needs a folder of fitted scenes"),
        (("--scenes", str(scenes), "--role", "proxy", "--checkpoint", "c"), "--upstream: give the upstream"),
        (
            ("--scenes", str(scenes), "--role", "proxy", "--upstream", "h:1"),
            "--checkpoint: the proxy enhances",
        ),
        (("--scenes", str(scenes), "--host", "0.0.0.0"), "--host: 0.0.0.0 is not a loopback address"),
    ):
        with pytest.raises(UsageError) as caught:
            settings(*words)
        assert caught.value.one_line().startswith(message)
