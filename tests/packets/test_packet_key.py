"""``PacketKey``: the one declaration of a packet's identity, shared by plan, store, packets, target refs
and run rows."""

from __future__ import annotations

from dataclasses import fields

from setdiff_bench.io.run_layout import KEY_COLUMNS
from setdiff_bench.packets.jobs import PacketJob
from setdiff_bench.packets.writer import PacketHeader
from setdiff_bench.types import PACKET_KEY_FIELDS, Packet, PacketKey, TargetRef


def test_everything_that_names_a_packet_extends_the_key() -> None:
    for cls in (PacketJob, PacketHeader, TargetRef):
        assert issubclass(cls, PacketKey)
        assert tuple(f.name for f in fields(cls))[: len(PACKET_KEY_FIELDS)] == PACKET_KEY_FIELDS


def test_packet_carries_the_key_fields_in_key_order() -> None:
    assert tuple(f.name for f in fields(Packet))[: len(PACKET_KEY_FIELDS)] == PACKET_KEY_FIELDS


def test_key_from_a_row_and_back() -> None:
    row = {
        "packet_id": "p",
        "dataset": "d",
        "protocol": "q",
        "group": "g",
        "split": "test",
        "scene": "s",
        "frame": "a.png",
    }
    ref = TargetRef.from_row(row, frame=row["frame"])
    assert ref.key == PacketKey("p", "d", "q", "g", "test", "s")
    assert ref.frame == "a.png"


def test_run_key_columns_hold_the_packet_key() -> None:
    assert set(PACKET_KEY_FIELDS) <= set(KEY_COLUMNS)
    assert KEY_COLUMNS[: len(PACKET_KEY_FIELDS) - 1] == PACKET_KEY_FIELDS[1:]
