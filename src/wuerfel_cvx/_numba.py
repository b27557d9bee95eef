"""The decorator that compiles the step path's kernels with numba (a core dependency).

The kernels (the compiled loops of :mod:`~wuerfel_cvx.step.contacts`, the contact search and
the contact matcher, of :mod:`~wuerfel_cvx.formulations.rows`,
:mod:`~wuerfel_cvx.formulations.motion` and :mod:`~wuerfel_cvx.formulations.velocity` (the
closest approach), of :mod:`~wuerfel_cvx.step.criteria`,
:mod:`~wuerfel_cvx.step.simulation` and :mod:`~wuerfel_cvx.step.metrics` (the physical
check, the new state's finite check, the rod drifts),
:mod:`~wuerfel_cvx.solve.residual_kernel`, :func:`~wuerfel_cvx._sparse.add_rows` and the
polish's sparse ``L D L'``) are plain Python functions over arrays;
:func:`compiled` hands them to ``numba.njit`` with its default strict IEEE semantics (no
fast-math: no reassociation, no fused multiply-add), so each operation rounds as NumPy's
does.  The machine code is cached on disk (next to the sources, or in ``NUMBA_CACHE_DIR``),
so only a process that finds no cache pays the compilation.  The NumPy versions they replaced are
kept in ``tests/reference_kernels.py`` and checked against them bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numba

_Function = TypeVar("_Function", bound=Callable[..., Any])


def compiled(function: _Function) -> _Function:
    """``function`` compiled by numba, its machine code cached on disk."""
    try:
        return numba.njit(cache=True, nogil=True)(function)  # type: ignore[return-value]
    except RuntimeError:  # pragma: no cover - no writable cache directory: compile per process
        return numba.njit(cache=False, nogil=True)(function)  # type: ignore[return-value]


@compiled
def running_max(largest: float, value: float) -> float:
    """``np.max`` of ``largest`` and ``value`` when neither is below +0: a NaN is kept.

    The kernels' running maxima: of numbers that are +0, positive or NaN the maximum is one
    number whatever the order (no two signed zeros to choose from), so a running maximum
    gives NumPy's.
    """
    if largest != largest:
        return largest
    return value if value > largest or value != value else largest
