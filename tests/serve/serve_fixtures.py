"""Helpers of the service tests: the shipped enhancers, test certificates, a served CLI process, a light client
process (grpc and the generated messages only) that drives a session until it is killed."""

from __future__ import annotations

import datetime
import ipaddress
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from setdiff_bench.models.setdiff.packaged import packaged_models

ROOT = Path(__file__).resolve().parents[2]

#: ``(name, method)`` of every shipped enhancer (``setdiff-bench weights list``), sparse-view ones included
#: once they ship.
SHIPPED_ENHANCERS: list[tuple[str, str]] = [
    (name, str(model.manifest["method"]))
    for name, model in packaged_models().items()
    if model.kind == "enhancer"
]


def environment(**extra: str) -> dict[str, str]:
    """The environment of a child process: one thread, this checkout importable."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "SETDIFF_THREADS": "1", "PYTHONPATH": str(ROOT)}
    env.pop("SETDIFF_SERVE_TOKEN", None)
    env.update(extra)
    return env


@contextmanager
def served(argv: list[str], env: dict[str, str] | None = None) -> Iterator[tuple[subprocess.Popen[str], int]]:
    """``python -m setdiff_bench serve ...`` in its own process; yields it and the port it printed."""
    process = subprocess.Popen(
        [sys.executable, "-m", "setdiff_bench", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env or environment(),
    )
    try:
        line = process.stdout.readline()
        if not line.startswith("serving on "):
            process.wait(timeout=60)
            raise AssertionError(f"serve did not start: {line!r} {process.stderr.read()!r}")
        yield process, int(line.split(":")[1].split()[0])
    finally:
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


# ---------------------------------------------------------------------------------------------- certificates
@dataclass(frozen=True)
class Certificates:
    """PEM files made for one test: a CA, a server certificate it signed (localhost, 127.0.0.1), a client
    certificate it signed, and a client certificate of another CA."""

    ca: Path
    server_cert: Path
    server_key: Path
    client_cert: Path
    client_key: Path
    rogue_cert: Path
    rogue_key: Path


def make_certificates(folder: Path) -> Certificates:
    """Write a fresh CA, server and client certificates (EC P-256, valid one day) into ``folder``."""
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    now = datetime.datetime.now(datetime.UTC)
    folder.mkdir(parents=True, exist_ok=True)

    def name(common: str) -> x509.Name:
        return x509.Name([x509.NameAttribute(NameOID.COMMON_NAME, common)])

    def key_and_file(stem: str) -> tuple[ec.EllipticCurvePrivateKey, Path]:
        key = ec.generate_private_key(ec.SECP256R1())
        path = folder / f"{stem}.key"
        path.write_bytes(
            key.private_bytes(
                serialization.Encoding.PEM,
                serialization.PrivateFormat.PKCS8,
                serialization.NoEncryption(),
            )
        )
        return key, path

    def certificate(
        stem: str,
        subject: str,
        key: ec.EllipticCurvePrivateKey,
        issuer: tuple[x509.Name, ec.EllipticCurvePrivateKey] | None,
        *,
        ca: bool = False,
        usage: x509.ObjectIdentifier | None = None,
        names: list[x509.GeneralName] | None = None,
    ) -> Path:
        issuer_name, issuer_key = issuer or (name(subject), key)
        builder = (
            x509.CertificateBuilder()
            .subject_name(name(subject))
            .issuer_name(issuer_name)
            .public_key(key.public_key())
            .serial_number(x509.random_serial_number())
            .not_valid_before(now - datetime.timedelta(minutes=5))
            .not_valid_after(now + datetime.timedelta(days=1))
            .add_extension(x509.BasicConstraints(ca=ca, path_length=None), critical=True)
        )
        if usage is not None:
            builder = builder.add_extension(x509.ExtendedKeyUsage([usage]), critical=False)
        if names:
            builder = builder.add_extension(x509.SubjectAlternativeName(names), critical=False)
        path = folder / f"{stem}.pem"
        path.write_bytes(builder.sign(issuer_key, hashes.SHA256()).public_bytes(serialization.Encoding.PEM))
        return path

    ca_key, _ = key_and_file("ca")
    ca = certificate("ca", "setdiff test CA", ca_key, None, ca=True)
    server_key, server_key_path = key_and_file("server")
    server = certificate(
        "server",
        "localhost",
        server_key,
        (name("setdiff test CA"), ca_key),
        usage=ExtendedKeyUsageOID.SERVER_AUTH,
        names=[x509.DNSName("localhost"), x509.IPAddress(ipaddress.ip_address("127.0.0.1"))],
    )
    client_key, client_key_path = key_and_file("client")
    client = certificate(
        "client",
        "simulator",
        client_key,
        (name("setdiff test CA"), ca_key),
        usage=ExtendedKeyUsageOID.CLIENT_AUTH,
    )
    rogue_ca_key, _ = key_and_file("rogue_ca")
    rogue_key, rogue_key_path = key_and_file("rogue")
    rogue = certificate(
        "rogue",
        "intruder",
        rogue_key,
        (name("rogue CA"), rogue_ca_key),
        usage=ExtendedKeyUsageOID.CLIENT_AUTH,
    )
    return Certificates(ca, server, server_key_path, client, client_key_path, rogue, rogue_key_path)


# ---------------------------------------------------------------------------------------------- light clients
#: A simulator process: opens a session (retrying while the server is full), prints ``tick N`` after each
#: enhanced tick, and never closes the session -- it drives until it is killed.
DRIVER = r"""
import sys, time, grpc
from setdiff_bench.serve import enhancer_pb2 as pb, enhancer_pb2_grpc as pb_grpc
address, start_file, tick_file = sys.argv[1:4]
options = [("grpc.max_receive_message_length", 1 << 28), ("grpc.max_send_message_length", 1 << 28)]
stub = pb_grpc.EnhancerStub(grpc.insecure_channel(address, options=options))
start = pb.StartSessionRequest.FromString(open(start_file, "rb").read())
tick = pb.EnhanceRequest.FromString(open(tick_file, "rb").read())
deadline = time.monotonic() + 60
while True:
    try:
        session = stub.start_session(start, timeout=30).session_uuid
        break
    except grpc.RpcError as error:
        if error.code() != grpc.StatusCode.RESOURCE_EXHAUSTED or time.monotonic() > deadline:
            print("refused", error.code(), error.details(), flush=True)
            sys.exit(1)
        time.sleep(0.1)
tick.session_uuid = session
n = 0
while True:
    stub.enhance(tick, timeout=30)
    n += 1
    print(f"tick {n}", flush=True)
"""


def start_driver(address: str, start_file: Path, tick_file: Path) -> subprocess.Popen[str]:
    """A :data:`DRIVER` process against ``address`` with these serialised requests."""
    return subprocess.Popen(
        [sys.executable, "-c", DRIVER, address, str(start_file), str(tick_file)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=environment(),
    )
