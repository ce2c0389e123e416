"""simcore.world.native_calls and conditions.compare_floats: what the compiled step loop calls instead of `bisect`,
`math` look-ups and the comparison rules gives what those give."""

from __future__ import annotations

import bisect
import math

from hypothesis import given
from hypothesis import strategies as st

from simcore.world.native_calls import atan2, bisect_right, hypot

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@given(st.lists(finite, max_size=40), st.floats(width=64))
def test_bisect_right_gives_the_index_bisect_gives(values: list[float], x: float) -> None:
    values.sort()
    assert bisect_right(values, x) == bisect.bisect_right(values, x)


@given(st.lists(st.sampled_from([0.0, 1.0, 2.5]), max_size=12), st.sampled_from([-1.0, 0.0, 1.0, 2.5, 3.0]))
def test_bisect_right_goes_past_equal_values_as_bisect_does(values: list[float], x: float) -> None:
    values.sort()
    assert bisect_right(values, x) == bisect.bisect_right(values, x)


def test_bisect_right_of_nothing_and_of_nan() -> None:
    assert bisect_right([], 1.0) == 0
    assert bisect_right([0.0, 1.0, 2.0], math.nan) == bisect.bisect_right([0.0, 1.0, 2.0], math.nan) == 3


def test_the_math_functions_are_maths() -> None:
    assert hypot is math.hypot and atan2 is math.atan2


@given(
    st.sampled_from(["greaterThan", "lessThan", "equalTo", "greaterOrEqual", "lessOrEqual", "notEqualTo"]),
    st.floats(width=64),
    st.one_of(st.floats(width=64), st.sampled_from([0.0, -0.0, 1e-10, 1.0])),
)
def test_compare_floats_answers_as_the_rules_of_compare(rule: str, a: float, b: float) -> None:
    from simcore.scenario.conditions import compare, compare_floats

    assert compare_floats(rule, a, b) == compare(rule, a, b)
    assert compare_floats(rule, a, a + 1e-12) == compare(rule, a, a + 1e-12)
