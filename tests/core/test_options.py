"""``parse_option``: the one ``KEY=VALUE`` parser (``-o/--option`` and ``prepare --loader-option``)."""

from __future__ import annotations

import pytest

from setdiff_bench.cli import parse_option
from setdiff_bench.errors import UsageError


def test_values_parse_as_json_else_text() -> None:
    assert parse_option("level=1") == ("level", 1)
    assert parse_option("sweeps=false") == ("sweeps", False)
    assert parse_option('channels=["CAM_FRONT"]') == ("channels", ["CAM_FRONT"])
    assert parse_option("version=v1.0-mini") == ("version", "v1.0-mini")
    assert parse_option("a=b=c") == ("a", "b=c")
    assert parse_option(" key =") == ("key", "")


@pytest.mark.parametrize("text", ["tolerance", "=1", " =1"])
def test_bad_option_names_the_flag(text: str) -> None:
    with pytest.raises(UsageError, match="must look like KEY=VALUE") as info:
        parse_option(text)
    assert info.value.path == "-o/--option"
    with pytest.raises(UsageError) as info:
        parse_option(text, "--loader-option")
    assert info.value.path == "--loader-option" and len(str(info.value).splitlines()) == 1


def test_prepare_has_no_second_parser() -> None:
    from setdiff_bench.cli import prepare

    assert not hasattr(prepare, "parse_loader_options")
