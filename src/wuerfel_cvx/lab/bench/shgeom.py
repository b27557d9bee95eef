"""The shifted geometric mean, the usual summary of solver running times.

The geometric mean of times compares solvers by ratios ("twice as fast") rather than by
absolute differences, so that one long grid point does not outweigh a hundred short ones.
Taken as is, it is dominated by the *smallest* times instead: a step of 0.01 ms against one
of 0.02 ms weighs as much as 10 ms against 20 ms, although the first difference is below
the timer's noise.  A zero time makes it zero.  The shifted geometric mean

    sgm_s(t_1 .. t_n) = exp(mean(log(t_i + s))) - s

adds a shift ``s`` (in the unit of the times) before taking logarithms and subtracts it
afterwards: times much larger than ``s`` still count by their ratios, times much smaller
count roughly by their absolute differences, i.e. hardly at all.  Mittelmann's solver
benchmarks and Achterberg's SCIP thesis use ``s = 10 s`` for solve times of seconds to
hours; the shift is chosen near the smallest times whose differences still matter.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

DEFAULT_TIME_SHIFT = 1e-4
"""Shift (s) for per-step times of this package: 0.1 ms.

Per-step wall, solver and modelling times in the benchmark span about 0.05 ms (a
one-square QP, or the solver's own time of a tiny QP) to 20 ms (a 200-square pyramid).
A shift of 0.1 ms

* damps the tiny times: 0.05 ms against 0.1 ms, a ratio of 2 that is mostly timer and
  scheduler jitter (tens of microseconds), becomes (0.15 / 0.2), a ratio of 1.33;
* leaves the typical times almost untouched: 2 ms against 4 ms (a ratio of 2) becomes
  2.1 ms against 4.1 ms (1.95), and 10 ms against 20 ms stays at 1.99;
* makes zeros harmless (a solver that reports no time of its own).

A shift of 1 ms would swamp the typical times (2 ms against 4 ms would count as 1.67), one
of 0.01 ms would let sub-jitter differences count as full ratios again.
"""


def shifted_geometric_mean(values: Iterable[float], shift: float = DEFAULT_TIME_SHIFT) -> float:
    """The shifted geometric mean ``exp(mean(log(v + shift))) - shift`` of ``values``.

    Parameters
    ----------
    values:
        Non-negative numbers, e.g. times in seconds; at least one.
    shift:
        Shift in the unit of ``values`` (default :data:`DEFAULT_TIME_SHIFT`, 1e-4 s);
        must be non-negative.  ``shift = 0`` gives the plain geometric mean.

    Returns
    -------
    float
        The mean, in the unit of ``values``.

    Raises
    ------
    ValueError
        If ``values`` is empty, holds a non-finite value, or ``v + shift <= 0`` for some
        value (a negative time, or a zero with ``shift = 0``).

    """
    if not (math.isfinite(shift) and shift >= 0):
        raise ValueError(f"shift must be finite and non-negative, got {shift}")
    numbers = [float(value) for value in values]
    if not numbers:
        raise ValueError("the shifted geometric mean of no values is undefined")
    for value in numbers:
        if not math.isfinite(value) or value + shift <= 0:
            raise ValueError(f"value {value} with shift {shift}: needs finite v + shift > 0")
    mean_log = math.fsum(math.log(value + shift) for value in numbers) / len(numbers)
    return math.exp(mean_log) - shift
