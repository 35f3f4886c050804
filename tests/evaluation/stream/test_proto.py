"""The committed generated code was made from the committed ``enhancer.proto`` (compared as descriptors,
which do not depend on the grpcio-tools version)."""

from __future__ import annotations

from pathlib import Path

import pytest
from google.protobuf import descriptor_pb2

from setdiff_bench.serve import enhancer_pb2

ROOT = Path(__file__).resolve().parents[3]


def test_generated_code_matches_proto(tmp_path: Path) -> None:
    protoc = pytest.importorskip("grpc_tools.protoc")
    out = tmp_path / "enhancer.desc"
    assert (
        protoc.main(
            ["protoc", f"-I{ROOT}", f"--descriptor_set_out={out}", "setdiff_bench/serve/enhancer.proto"]
        )
        == 0
    )
    compiled = descriptor_pb2.FileDescriptorSet.FromString(out.read_bytes()).file[0]
    for message in compiled.message_type:  # protoc's --python_out drops the derived json_name
        for field in message.field:
            field.ClearField("json_name")
    committed = descriptor_pb2.FileDescriptorProto.FromString(enhancer_pb2.DESCRIPTOR.serialized_pb)
    assert compiled == committed
