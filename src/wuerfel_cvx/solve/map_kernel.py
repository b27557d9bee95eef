"""Dense constraint rows as a compiled loop.

:func:`add_rows` writes DAQP's and PROXQP's dense constraint rows
(:func:`wuerfel_cvx._sparse.dense_rows`, bit for bit scipy's ``toarray``,
``tests/test_dense_forms.py``) in one loop: a few NumPy operations per call, whose
overhead outweighs their work on a small scene.
"""

from __future__ import annotations

import numpy as np

from .._numba import compiled
from ..scenes.geometry import FloatArray

__all__ = ["add_rows"]


@compiled
def add_rows(data: FloatArray, indices: np.ndarray, indptr: np.ndarray,
             out: FloatArray) -> None:
    """Add canonical CSR rows' entries to ``out``'s rows, in place, as ``toarray`` does."""
    for row in range(indptr.shape[0] - 1):
        for k in range(indptr[row], indptr[row + 1]):
            out[row, indices[k]] += data[k]

