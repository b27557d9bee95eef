"""numba, if installed: the decorator that compiles the step path's kernels.

The kernels (:mod:`~wuerfel_cvx.contact_kernel`, :mod:`~wuerfel_cvx.row_kernel`) are plain
Python functions over arrays; :func:`compiled` hands them to ``numba.njit`` with its
default strict IEEE semantics (no fast-math: no reassociation, no fused multiply-add), so
each operation rounds as NumPy's does.  Without numba (an optional dependency, the
``fast`` extra) :data:`AVAILABLE` is false, the functions stay plain Python, and the
callers run their NumPy paths instead.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

try:  # numba is optional: every kernel has a NumPy reference path
    import numba
except ImportError:  # pragma: no cover - exercised where numba is not installed
    numba = None  # type: ignore[assignment]

AVAILABLE = numba is not None
"""Whether the compiled kernels can run (numba is importable)."""

enabled = AVAILABLE
"""Whether the step path runs the compiled kernels (default: when numba is installed);
``False`` runs the NumPy reference paths, with the same results bit for bit."""

_Function = TypeVar("_Function", bound=Callable[..., Any])


def compiled(function: _Function) -> _Function:
    """``function`` compiled by numba (machine code cached on disk), or itself without numba."""
    if numba is None:  # pragma: no cover
        return function
    try:
        return numba.njit(cache=True, nogil=True)(function)  # type: ignore[return-value]
    except RuntimeError:  # pragma: no cover - no writable cache directory: compile per process
        return numba.njit(cache=False, nogil=True)(function)  # type: ignore[return-value]
