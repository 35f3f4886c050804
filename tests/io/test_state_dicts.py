"""``io.state_dicts.state_dict_problem``: the first problem of a weights file, in the documented order."""

from __future__ import annotations

import numpy as np
import torch

from setdiff_bench.io.state_dicts import shapes_of, state_dict_problem

EXPECTED = {"a.weight": (2, 3), "a.bias": (2,), "bn.num_batches_tracked": ()}


def _state(**changes: object) -> dict[str, torch.Tensor]:
    state = {
        "a.weight": torch.zeros(2, 3),
        "a.bias": torch.zeros(2),
        "bn.num_batches_tracked": torch.tensor(0),
    }
    for name, value in changes.items():
        key = name.replace("__", ".")
        if value is None:
            state.pop(key)
        else:
            state[key] = value  # type: ignore[assignment]
    return state


def test_a_fitting_state_has_no_problem_and_optional_names_may_be_absent() -> None:
    assert state_dict_problem(EXPECTED, _state()) is None
    lenient = state_dict_problem(
        EXPECTED, _state(bn__num_batches_tracked=None), optional=lambda n: "batches" in n
    )
    assert lenient is None
    strict = state_dict_problem(EXPECTED, _state(bn__num_batches_tracked=None))
    assert strict is not None and strict.kind == "missing" and strict.names == ["bn.num_batches_tracked"]


def test_names_come_before_shapes_and_report_both_sides() -> None:
    state = _state(a__bias=None, extra=torch.zeros(1), a__weight=torch.zeros(3, 2))
    problem = state_dict_problem(EXPECTED, state)
    assert problem is not None and problem.kind == "missing"
    assert problem.missing == ("a.bias",) and problem.unexpected == ("extra",)
    only_extra = state_dict_problem(EXPECTED, _state(extra=torch.zeros(1)))
    assert only_extra is not None and only_extra.kind == "unexpected" and only_extra.names == ["extra"]


def test_shape_dtype_and_values_in_that_order() -> None:
    shape = state_dict_problem(EXPECTED, _state(a__weight=torch.zeros(3, 2)))
    assert shape is not None and (shape.kind, shape.names, shape.found, shape.expected) == (
        "shape",
        ["a.weight"],
        (3, 2),
        (2, 3),
    )
    float64 = _state(a__weight=torch.zeros(2, 3, dtype=torch.float64))
    assert state_dict_problem(EXPECTED, float64) is None  # dtype unchecked unless asked
    dtype = state_dict_problem({"a.weight": (2, 3)}, {"a.weight": np.zeros((2, 3))}, float32=True)
    assert dtype is not None and dtype.kind == "dtype" and dtype.found == np.float64
    nan = _state(a__bias=torch.tensor([0.0, float("nan")]))
    assert state_dict_problem(EXPECTED, nan) is None  # values unchecked unless asked
    problem = state_dict_problem(EXPECTED, nan, finite=True)
    assert problem is not None and problem.kind == "non_finite" and problem.names == ["a.bias"]


def test_shapes_of_a_module() -> None:
    assert shapes_of(torch.nn.Linear(3, 2).state_dict()) == {"weight": (2, 3), "bias": (2,)}
