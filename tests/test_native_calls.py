"""simcore.world.native_calls: what the compiled step loop calls instead of `bisect` and `math` look-ups
gives what those give."""

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
