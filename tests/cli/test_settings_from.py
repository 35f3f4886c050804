"""``cli.settings_from``: parsed arguments into a verb's settings dataclass, fields by their own names."""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from setdiff_bench.cli import settings_from


@dataclasses.dataclass(frozen=True)
class _Settings:
    host: str
    port: int
    token: str | None = None


def test_fields_come_from_arguments_unless_derived() -> None:
    args = argparse.Namespace(host="127.0.0.1", port=50051, token="from-args", unrelated=1)
    assert settings_from(_Settings, args) == _Settings("127.0.0.1", 50051, "from-args")
    assert settings_from(_Settings, args, token="derived") == _Settings("127.0.0.1", 50051, "derived")


def test_a_field_neither_derived_nor_parsed_is_a_programming_error() -> None:
    with pytest.raises(TypeError, match=r"_Settings\.port: neither derived nor a parsed argument"):
        settings_from(_Settings, argparse.Namespace(host="h"))
