"""The refit schedule's settings: presets, the real/pseudo interleave and the update steps, hand-derived."""

from __future__ import annotations

import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.refit import RefitSettings


def test_presets_set_the_papers_schedules() -> None:
    progressive = RefitSettings.preset("progressive")
    assert (progressive.update_every, progressive.pose_fraction) == (100, 0.5)
    assert (progressive.pseudo_weight, progressive.real_ratio) == (0.3, 0.7)  # Difix3D+: w 0.3, 70 % real
    one_shot = RefitSettings.preset("one-shot", steps=40)
    assert (one_shot.update_every, one_shot.pose_fraction, one_shot.steps) == (0, 1.0, 40)
    assert one_shot.update_steps() == [0]


def test_update_steps_every_n() -> None:
    assert RefitSettings.preset("progressive", steps=300, update_every=100).update_steps() == [0, 100, 200]
    assert RefitSettings.preset("progressive", steps=7, update_every=3).update_steps() == [0, 3, 6]


def test_pseudo_steps_are_spread_at_the_ratio() -> None:
    # r = 0.7: step n is pseudo when floor(0.3 n) grows, i.e. at n = 4, 7, 10 (0.3 n = 1.2, 2.1, 3.0)
    settings = RefitSettings.preset("progressive", real_ratio=0.7)
    assert [n for n in range(1, 11) if settings.is_pseudo_step(n)] == [4, 7, 10]
    half = RefitSettings.preset("progressive", real_ratio=0.5)
    assert [n for n in range(1, 7) if half.is_pseudo_step(n)] == [2, 4, 6]
    assert all(RefitSettings.preset("one-shot", real_ratio=0.0).is_pseudo_step(n) for n in range(1, 5))


@pytest.mark.parametrize(
    ("overrides", "option"),
    [
        ({"steps": 0}, "--steps"),
        ({"pose_fraction": 0.0}, "--pose-fraction"),
        ({"pose_fraction": 1.5}, "--pose-fraction"),
        ({"real_ratio": 1.0}, "--real-ratio"),
        ({"pseudo_weight": -1.0}, "--pseudo-weight"),
        ({"update_every": -1}, "--update-every"),
    ],
)
def test_out_of_range_values_name_their_option(overrides: dict[str, float], option: str) -> None:
    with pytest.raises(UsageError) as error:
        RefitSettings.preset("progressive", **overrides)
    assert error.value.path == option


def test_unknown_schedule_is_refused() -> None:
    with pytest.raises(UsageError, match="one-shot"):
        RefitSettings.preset("sometimes")
