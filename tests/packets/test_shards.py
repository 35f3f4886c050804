"""``Shard``: the one ``--shard i/n`` parser, used by ``prepare`` and ``run``."""

from __future__ import annotations

import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.packets.shards import Shard


def test_parse_and_select() -> None:
    assert Shard.parse("1/4") == Shard(1, 4)
    assert Shard.parse("0/1") == Shard()
    assert str(Shard(1, 4)) == "1/4"
    assert Shard(1, 3).select(["a", "b", "c", "d", "e"]) == ["b", "e"]


@pytest.mark.parametrize("text", ["4/4", "x", "1/0", "-1/2", "1-2", "3"])
def test_bad_shard_is_one_line_usage_error(text: str) -> None:
    with pytest.raises(UsageError) as info:
        Shard.parse(text)
    message = str(info.value)
    assert "--shard" in message and len(message.splitlines()) == 1


def test_prepare_and_run_share_the_parser() -> None:
    from setdiff_bench.evaluation.run import _method
    from setdiff_bench.packets import prepare, prepare_settings

    assert _method.Shard is Shard and prepare_settings.Shard is Shard
    assert not hasattr(prepare, "parse_shard")
