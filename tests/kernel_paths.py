"""Running a computation on the NumPy reference path and on the compiled kernels."""

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
