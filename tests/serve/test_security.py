"""TLS, mutual TLS and the bearer token with a real server on a free port (certificates made in the test), and
the bind rule: a non-loopback host without TLS and a token is refused in one line, exit 2."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import grpc
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.errors import UsageError
from setdiff_bench.serve.client import EnhancerClient
from setdiff_bench.serve.security import TOKEN_ENV, ServerTls, TokenSource, check_bind, is_loopback
from setdiff_bench.serve.server import RunningServer, start_server
from setdiff_bench.serve.settings import ServeSettings
from tests.evaluation.stream.stream_fixtures import HEIGHT, WIDTH, recorded_references, tick_frames
from tests.serve.serve_fixtures import Certificates, environment

#: The tests' 48×32 frames are smaller than the shipped models' 256×144: the domain warning is expected.
pytestmark = pytest.mark.filterwarnings("ignore::setdiff_bench.errors.OutOfDistributionWarning")

TOKEN = "s3cret-token-0123456789abcdef"


@pytest.fixture(scope="module")
def enhancer() -> Any:
    return load_enhancer("setdiff", "tiny_setdiff", device="cpu")


@contextmanager
def serving(enhancer: Any, **settings: Any) -> Iterator[RunningServer]:
    running = start_server(enhancer, ServeSettings(port=0, **settings))
    try:
        yield running
    finally:
        running.stop(grace=5)


def refused(call: Any) -> tuple[grpc.StatusCode, str]:
    with pytest.raises(grpc.RpcError) as caught:
        call()
    return caught.value.code(), caught.value.details()


def drive_one_tick(client: EnhancerClient) -> None:
    session = client.start_session(recorded_references())
    assert client.enhance(session, tick_frames(0)).shape == (3, HEIGHT, WIDTH, 3)
    client.close_session(session)


def test_token_is_checked_on_every_rpc_but_health(enhancer: Any, tmp_path: Path) -> None:
    token_file = tmp_path / "token"
    token_file.write_text(TOKEN + "\n")
    with serving(enhancer, token=TokenSource(file=token_file)) as running:
        address = f"127.0.0.1:{running.port}"
        with EnhancerClient(address, token=TokenSource(file=token_file)) as client:
            drive_one_tick(client)
            session = client.start_session(recorded_references())
        wrong_file = tmp_path / "wrong"
        wrong_file.write_text("not-the-token-0123456789")
        for token, words in (
            (None, "missing bearer token"),
            (TokenSource(file=wrong_file), "wrong or expired"),
        ):
            with EnhancerClient(address, token=token, timeout=10) as intruder:
                assert intruder.healthy()  # health needs no token
                calls = {
                    "start_session": lambda c=intruder: c.start_session(recorded_references()),
                    "enhance": lambda c=intruder: c.enhance(session, tick_frames(0)),
                    "close_session": lambda c=intruder: c.close_session(session),
                    "get_version": intruder.get_version,
                }
                for name, call in calls.items():
                    code, details = refused(call)
                    assert code == grpc.StatusCode.UNAUTHENTICATED and words in details, (name, details)
                    assert TOKEN not in details
                # nothing of the request is processed: undecodable bytes still get UNAUTHENTICATED
                raw = intruder.channel.unary_unary("/setdiff_bench.serve.v1.Enhancer/start_session")
                metadata = () if token is None else (("authorization", f"Bearer {token.current()}"),)
                code, _ = refused(
                    lambda raw=raw, metadata=metadata: raw(b"\xff\xff garbage", metadata=metadata)
                )
                assert code == grpc.StatusCode.UNAUTHENTICATED
        assert list(running.service.sessions) == [session]  # no session opened, none closed
        assert running.service.sessions[session].stream.ticks == 0  # no tick enhanced

        # rotation: the file is replaced; the old token is expired, the new one works
        (tmp_path / "old").write_text(TOKEN)
        old = TokenSource(file=tmp_path / "old")
        rotated = tmp_path / "token.new"
        rotated.write_text("rotated-token-9876543210fedcba")
        os.replace(rotated, token_file)
        with EnhancerClient(address, token=old) as stale:
            code, details = refused(stale.get_version)
            assert code == grpc.StatusCode.UNAUTHENTICATED and "expired" in details
        with EnhancerClient(address, token=TokenSource(file=token_file)) as client:
            client.close_session(session)


def test_token_from_the_environment(enhancer: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(TOKEN_ENV, TOKEN)
    with serving(enhancer, token=TokenSource(env=TOKEN_ENV)) as running:
        with EnhancerClient(f"127.0.0.1:{running.port}", token=TokenSource(env=TOKEN_ENV)) as client:
            drive_one_tick(client)
        with EnhancerClient(f"127.0.0.1:{running.port}") as client:
            assert refused(client.get_version)[0] == grpc.StatusCode.UNAUTHENTICATED
    assert TOKEN not in repr(TokenSource(env=TOKEN_ENV)) and TOKEN not in repr(
        ServeSettings(token=TokenSource(env=TOKEN_ENV))
    )
    monkeypatch.setenv(TOKEN_ENV, "short")
    with pytest.raises(UsageError, match="at least 16"):
        TokenSource(env=TOKEN_ENV)


def test_tls_with_a_certificate_made_in_the_test(
    enhancer: Any, certificates: Certificates, tmp_path: Path
) -> None:
    token_file = tmp_path / "token"
    token_file.write_text(TOKEN)
    tls = ServerTls.from_files(certificates.server_cert, certificates.server_key)
    with serving(enhancer, tls=tls, token=TokenSource(file=token_file)) as running:
        for address in (f"localhost:{running.port}", f"127.0.0.1:{running.port}"):  # both in the certificate
            with EnhancerClient(
                address, tls_ca=certificates.ca, token=TokenSource(file=token_file)
            ) as client:
                drive_one_tick(client)
        with EnhancerClient(
            f"127.0.0.1:{running.port}", token=TokenSource(file=token_file), timeout=5
        ) as plain:
            assert (
                refused(plain.get_version)[0] == grpc.StatusCode.UNAVAILABLE
            )  # plaintext cannot talk to TLS
        with EnhancerClient(
            f"127.0.0.1:{running.port}",
            tls_ca=certificates.rogue_cert,
            token=TokenSource(file=token_file),
            timeout=5,
        ) as untrusting:
            assert (
                refused(untrusting.get_version)[0] == grpc.StatusCode.UNAVAILABLE
            )  # server cert not trusted
        with EnhancerClient(f"127.0.0.1:{running.port}", tls_ca=certificates.ca) as tokenless:
            assert refused(tokenless.get_version)[0] == grpc.StatusCode.UNAUTHENTICATED


def test_mutual_tls(enhancer: Any, certificates: Certificates) -> None:
    tls = ServerTls.from_files(certificates.server_cert, certificates.server_key, certificates.ca)
    with serving(enhancer, tls=tls) as running:
        address = f"127.0.0.1:{running.port}"
        with EnhancerClient(
            address,
            tls_ca=certificates.ca,
            client_cert=certificates.client_cert,
            client_key=certificates.client_key,
        ) as client:
            drive_one_tick(client)
        with EnhancerClient(address, tls_ca=certificates.ca, timeout=5) as anonymous:
            assert refused(anonymous.get_version)[0] == grpc.StatusCode.UNAVAILABLE
        with EnhancerClient(
            address,
            tls_ca=certificates.ca,
            client_cert=certificates.rogue_cert,
            client_key=certificates.rogue_key,
            timeout=5,
        ) as rogue:
            assert refused(rogue.get_version)[0] == grpc.StatusCode.UNAVAILABLE
        assert not running.service.sessions


def test_bind_rule(tmp_path: Path) -> None:
    (tmp_path / "token").write_text(TOKEN)
    token = TokenSource(file=tmp_path / "token")
    assert all(is_loopback(h) for h in ("127.0.0.1", "127.1.2.3", "localhost", "::1", "[::1]"))
    assert not any(is_loopback(h) for h in ("0.0.0.0", "::", "10.0.0.5", "sim-gpu-3"))
    with pytest.raises(UsageError, match="not a loopback address"):
        check_bind("0.0.0.0", None, token, False)  # a token alone is not enough
    check_bind("0.0.0.0", None, None, True)  # --insecure
    check_bind("127.0.0.1", None, None, False)


def test_serve_refuses_a_public_bind_without_tls_and_token_in_one_line() -> None:
    """In its own process, as typed: exit 2, one stderr line, nothing served (the model is not even loaded)."""
    result = subprocess.run(
        [sys.executable, "-m", "setdiff_bench", "serve", "--checkpoint", "tiny_setdiff", "--host", "0.0.0.0"],
        capture_output=True,
        text=True,
        env=environment(),
        timeout=120,
    )
    assert result.returncode == 2 and result.stdout == ""
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and "0.0.0.0 is not a loopback address" in lines[0] and "--insecure" in lines[0], (
        lines
    )


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--token", TOKEN], "never give the token on the command line"),
        (["--tls-cert", "missing.pem", "--tls-key", "missing.key"], "missing.pem: not found"),
        (["--tls-client-ca", "ca.pem"], "mutual TLS needs --tls-cert"),
        (["--session-idle-timeout", "0"], "--session-idle-timeout"),
        (["--max-session-mib", "nan"], "--max-session-mib"),
    ],
)
def test_bad_security_options_are_one_line(
    extra: list[str],
    words: str,
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["serve", "--checkpoint", "tiny_setdiff", "--port", "0", *extra]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and words in err, err
    assert TOKEN not in err


def test_port_in_use_prints_one_line(enhancer: Any) -> None:
    """Issue 45 defect 6: grpc core's own 'Failed to add port' line no longer precedes ours."""
    with serving(enhancer) as running:
        result = subprocess.run(
            [
                sys.executable,
                "-m",
                "setdiff_bench",
                "serve",
                "--checkpoint",
                "tiny_setdiff",
                "--device",
                "cpu",
                "--port",
                str(running.port),
            ],
            capture_output=True,
            text=True,
            env=environment(),
            timeout=120,
        )
    assert result.returncode == 2
    assert result.stderr.splitlines() == [
        f"setdiff-bench serve: error: 127.0.0.1:{running.port}: cannot bind (address in use or not available)"
    ]


def test_ply_path_is_confined_to_the_ply_root(enhancer: Any, tmp_path: Path) -> None:
    """A session may name a PLY (its C-maps are then rendered) only relative to --ply-root."""
    import torch

    from setdiff_bench.evaluation.stream import Views
    from setdiff_bench.gaussians.model import GaussianModel
    from setdiff_bench.gaussians.ply import write_ply

    generator = torch.Generator().manual_seed(0)
    count = 300
    means = torch.rand(count, 3, generator=generator) * torch.tensor([12.0, 8.0, 3.0]) + torch.tensor(
        [14.0, 2.0, -0.5]
    )
    model = GaussianModel(
        means=means,
        quats=torch.tensor([[1.0, 0.0, 0.0, 0.0]]).repeat(count, 1),
        log_scales=torch.full((count, 3), -1.0),
        opacity_logits=torch.full((count,), 2.0),
        sh=torch.rand(count, 1, 3, generator=generator),
    )
    (tmp_path / "plys" / "drive").mkdir(parents=True)
    write_ply(tmp_path / "plys" / "drive" / "lane0.ply", model)
    (tmp_path / "plys" / "drive" / "notes.txt").write_text("not a PLY")
    write_ply(tmp_path / "outside.ply", model)
    references, frames = recorded_references(), tick_frames(0)
    bare_references = Views(references.images, references.cameras, names=references.names)
    with (
        serving(enhancer, ply_root=tmp_path / "plys") as running,
        EnhancerClient(f"127.0.0.1:{running.port}") as client,
    ):
        session = client.start_session(bare_references, ply_path="drive/lane0.ply")
        images = client.enhance(session, Views(frames.images, frames.cameras))  # C-maps rendered
        assert images.shape == (3, HEIGHT, WIDTH, 3)
        client.close_session(session)
        for bad in (
            "../outside.ply",
            str(tmp_path / "outside.ply"),
            "drive/notes.txt",
            "drive/missing.ply",
        ):
            code, details = refused(lambda bad=bad: client.start_session(bare_references, ply_path=bad))
            assert code == grpc.StatusCode.INVALID_ARGUMENT and "--ply-root" in details, (bad, details)
            assert str(tmp_path) not in details.replace(bad, "")  # the server's folders are not revealed
    with serving(enhancer) as running, EnhancerClient(f"127.0.0.1:{running.port}") as client:
        code, details = refused(lambda: client.start_session(bare_references, ply_path="drive/lane0.ply"))
        assert code == grpc.StatusCode.INVALID_ARGUMENT and "without --ply-root" in details


def test_example_client_takes_the_same_options(
    enhancer: Any, certificates: Certificates, tmp_path: Path
) -> None:
    """examples/drive_packets.py against a mutual-TLS server with a token: the client side of the options."""
    from setdiff_bench.evaluation.stream import StreamSession
    from setdiff_bench.packets.index import merge_index
    from tests.evaluation.stream.stream_fixtures import write_tick_store
    from tests.serve.serve_fixtures import ROOT

    references, frames = recorded_references(), tick_frames(0)
    chosen = StreamSession(enhancer, references).select(frames.cameras)
    write_tick_store(tmp_path / "store", references, frames, chosen, 0)
    merge_index(tmp_path / "store")
    (tmp_path / "token").write_text(TOKEN)
    tls = ServerTls.from_files(certificates.server_cert, certificates.server_key, certificates.ca)

    def example(*options: str) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [
                sys.executable,
                str(ROOT / "examples" / "drive_packets.py"),
                "--packets",
                str(tmp_path / "store"),
                "--out",
                str(tmp_path / "out"),
                "--address",
                address,
                *options,
            ],
            capture_output=True,
            text=True,
            env=environment(),
            timeout=300,
        )

    mutual = [
        "--tls-ca",
        str(certificates.ca),
        "--client-cert",
        str(certificates.client_cert),
        "--client-key",
        str(certificates.client_key),
    ]
    with serving(enhancer, tls=tls, token=TokenSource(file=tmp_path / "token")) as running:
        address = f"127.0.0.1:{running.port}"
        done = example(*mutual, "--token-file", str(tmp_path / "token"))
        assert done.returncode == 0, done.stderr
        assert len(list((tmp_path / "out").rglob("*.png"))) == 3
        tokenless = example(*mutual)
        assert tokenless.returncode == 1
        assert tokenless.stderr.splitlines() == [
            "drive_packets.py: error: UNAUTHENTICATED: missing bearer token (metadata 'authorization: Bearer <token>')"
        ]
        missing = example(*mutual, "--token-file", str(tmp_path / "nope"))
        assert (
            missing.returncode == 2
            and len(missing.stderr.splitlines()) == 1
            and "nope: not found" in missing.stderr
        )
