"""Running a computation on the NumPy path and on the compiled loops, where a module has both.

Only :mod:`wuerfel_cvx.backends._map` and :mod:`wuerfel_cvx.warm_start` still choose by
``_numba.enabled``; the rest of the step path runs its kernels only (their NumPy references
are in ``tests/reference_kernels.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TypeVar

import pytest

from wuerfel_cvx import _numba

Result = TypeVar("Result")


def both(monkeypatch: pytest.MonkeyPatch, build: Callable[[], Result]) -> list[Result]:
    """``build()`` on the NumPy path, then on the kernels (``[reference, compiled]``)."""
    results = []
    for enabled in (False, True):
        monkeypatch.setattr(_numba, "enabled", enabled)
        results.append(build())
    return results
