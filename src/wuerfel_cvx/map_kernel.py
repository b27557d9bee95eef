"""The direct path's gathers as compiled loops (numba), when numba is installed.

On the direct path (:mod:`wuerfel_cvx.backends`) each solve reads a solver's matrices and
right-hand sides out of the conic data's nonzeros (:class:`~wuerfel_cvx.backends._map.Gather`,
:class:`~wuerfel_cvx.backends._map.QPForm`) and our multipliers out of the solver's
(:meth:`~wuerfel_cvx.backends._map.ParameterMap.duals`): a few NumPy operations each (a
fancy index, a sign, a negation), whose per-call overhead outweighs their work on a small
scene.  The loops here do the same operations entry by entry (a product by a sign or a
coefficient rounds as NumPy's does), so they return the NumPy paths' numbers bit for bit
(``tests/test_map_kernel.py``), which stay the reference and run without numba.
"""

from __future__ import annotations

import numpy as np

from ._numba import AVAILABLE, compiled
from .geometry import FloatArray
from .model import IntArray

__all__ = ["AVAILABLE", "gather", "right_hand_sides", "scaled_take"]


@compiled
def gather(nonzeros: FloatArray, index: IntArray, sign: FloatArray, out: FloatArray) -> None:
    """``out = sign * nonzeros[index]``, in place."""
    for k in range(index.shape[0]):
        out[k] = sign[k] * nonzeros[index[k]]


@compiled
def right_hand_sides(nonzeros: FloatArray, b_index: IntArray, has_b: np.ndarray,
                     n_eq: int) -> tuple[FloatArray, FloatArray]:
    """``-b_cone[:n_eq]`` and ``b_cone[n_eq:]``, ``b_cone = where(has_b, nonzeros[b_index], 0)``."""
    rows = b_index.shape[0]
    equalities = np.empty(n_eq)
    inequalities = np.empty(rows - n_eq)
    for k in range(rows):
        value = nonzeros[b_index[k]] if has_b[k] else 0.0
        if k < n_eq:
            equalities[k] = -value
        else:
            inequalities[k - n_eq] = value
    return equalities, inequalities


@compiled
def scaled_take(multipliers: FloatArray, rows: IntArray, coefficients: FloatArray,
                offset: int, factor: float) -> FloatArray:
    """``(factor * coefficients) * multipliers[rows - offset]``; ``factor`` is 1.0 or -1.0."""
    out = np.empty(rows.shape[0])
    for k in range(rows.shape[0]):
        out[k] = (factor * coefficients[k]) * multipliers[rows[k] - offset]
    return out
