"""The one ``"module:attr"`` loader behind the method, dataset and metric registries."""

from __future__ import annotations

import os.path

import pytest

from setdiff_bench.errors import DatasetError, UsageError
from setdiff_bench.runtime.lazy import load_attribute


def test_good_reference_loads_the_named_object() -> None:
    assert load_attribute("os.path:join", "test") is os.path.join
    assert load_attribute("setdiff_bench.errors:UsageError", "test") is UsageError


@pytest.mark.parametrize(
    ("reference", "message"),
    [
        ("os.path.join", "thing 'x': 'os.path.join' is not 'module:attr'"),
        (":join", "thing 'x': ':join' is not 'module:attr'"),
        ("os.path:", "thing 'x': 'os.path:' is not 'module:attr'"),
        ("os:path:join", "thing 'x': 'os:path:join' is not 'module:attr'"),
        (".path:join", "thing 'x': '.path:join' is not 'module:attr'"),
        ("os.path:no_such_name", "thing 'x': os.path has no 'no_such_name' (from 'os.path:no_such_name')"),
    ],
)
def test_malformed_or_missing_attribute_is_one_usage_line(reference: str, message: str) -> None:
    with pytest.raises(UsageError) as caught:
        load_attribute(reference, "thing 'x'")
    assert str(caught.value) == message


def test_unimportable_module_is_one_line_naming_the_reference() -> None:
    with pytest.raises(UsageError) as caught:
        load_attribute("setdiff_bench.no_such_module:create", "method 'm' factory", path="plugins = m")
    text = str(caught.value)
    assert text.startswith(
        "plugins = m: method 'm' factory: cannot import setdiff_bench.no_such_module "
        "for 'setdiff_bench.no_such_module:create' ("
    )
    assert "\n" not in text


def test_caller_chooses_the_error_class_and_path() -> None:
    with pytest.raises(DatasetError) as caught:
        load_attribute("os:nope", "lister", error=DatasetError, path="registry")
    assert str(caught.value) == "registry: lister: os has no 'nope' (from 'os:nope')"


def test_registries_report_a_broken_reference_in_one_line() -> None:
    from setdiff_bench.enhancers.base import MethodSpec
    from setdiff_bench.loaders import DatasetSpec
    from setdiff_bench.metrics.registry import MetricSpec

    method = MethodSpec(name="m", factory="os:no_factory", description="", source="ep = os:no_factory")
    with pytest.raises(UsageError, match=r"^ep = os:no_factory: method 'm' factory: os has no 'no_factory'"):
        method.load_factory()
    dataset = DatasetSpec("d", "os.path", "os:nope", "")
    with pytest.raises(UsageError, match=r"^dataset 'd' lister: 'os.path' is not 'module:attr'$"):
        dataset.load_lister()
    with pytest.raises(UsageError, match=r"^dataset 'd' loader: os has no 'nope'"):
        dataset.load_loader()
    metric = MetricSpec("m", True, "setdiff_bench.metrics.nope:psnr", label="M", decimals=3)
    with pytest.raises(UsageError, match=r"^metric 'm': cannot import setdiff_bench.metrics.nope for "):
        metric.load()
