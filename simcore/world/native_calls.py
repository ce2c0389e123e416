"""The step loop's calls of `math` and `bisect` functions that mypyc does not compile to C calls, made
cheap for the compiled modules (`setup.py` COMPILED), with the same results:

- `math.hypot` and `math.atan2` fetched once: compiled, `math.hypot(...)` looks the function up in the
  module at every call (cos, sin and sqrt are C calls), while a name imported from here is read from a C
  static. The call itself stays a Python call.
- `bisect_right`, compiled itself: a call of `bisect.bisect_right` is a Python call, its float argument
  boxed and its index unboxed again.
"""

from __future__ import annotations

import math
from typing import Final

hypot: Final = math.hypot
atan2: Final = math.atan2


def bisect_right(a: list[float], x: float) -> int:
    """`bisect.bisect_right(a, x)`: the index after the last item of `a` that is not greater than `x`. The
    same comparisons (``x < a[mid]``), in the same order, as CPython's: the same index, also for a NaN."""
    lo = 0
    hi = len(a)
    while lo < hi:
        mid = (lo + hi) // 2
        if x < a[mid]:
            hi = mid
        else:
            lo = mid + 1
    return lo
