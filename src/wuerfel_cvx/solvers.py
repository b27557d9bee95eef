"""The solver registry and the one place where tolerances become solver options.

A tolerance is a preset name (``low``, ``default``, ``high``) or a number ``eps``;
:func:`solver_options` maps it to each solver's own option names.  ``high`` is the
tight setting used by the tests and as the reference.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import cvxpy as cp

from .errors import InputError

TOLERANCE_PRESETS: dict[str, float] = {"low": 1e-4, "default": 1e-7, "high": 1e-9}
"""Solver tolerance ``eps`` per preset (absolute and relative, in the QP's scaled units)."""


@cache
def _osqp_polish_option() -> str:
    """OSQP 1.0 renamed ``polish`` to ``polishing``."""
    try:
        major = int(version("osqp").split(".")[0])
    except PackageNotFoundError:
        return "polishing"
    return "polishing" if major >= 1 else "polish"


@dataclass(frozen=True)
class SolverSpec:
    """How to call one solver through cvxpy."""

    name: str
    """Registry name (upper case)."""
    cvxpy_name: str
    """Name of the solver in cvxpy."""
    options: Callable[[float], dict[str, Any]]
    """Solver options for tolerance ``eps``."""
    kind: str
    """``"interior-point"``, ``"ADMM"``, ``"proximal"``... for reports."""


SOLVERS: dict[str, SolverSpec] = {
    spec.name: spec
    for spec in (
        SolverSpec("CLARABEL", "CLARABEL", lambda eps: {
            "tol_gap_abs": eps, "tol_gap_rel": eps, "tol_feas": eps, "tol_ktratio": eps,
            "max_iter": 200}, "interior-point"),
        SolverSpec("OSQP", "OSQP", lambda eps: {
            "eps_abs": eps, "eps_rel": eps, _osqp_polish_option(): True, "max_iter": 200_000},
            "ADMM"),
        SolverSpec("PIQP", "PIQP", lambda eps: {
            "eps_abs": eps, "eps_rel": eps, "max_iter": 250, "compute_timings": True},
            "proximal interior-point"),
        # cvxpy (1.9) runs PROXQP's dense backend; its sparse one fails there with a
        # TypeError (cvxpy passes a box flag the sparse constructor does not take).
        SolverSpec("PROXQP", "PROXQP", lambda eps: {
            "eps_abs": eps, "eps_rel": 0.0, "max_iter": 10_000},
            "proximal augmented Lagrangian (dense backend)"),
        SolverSpec("SCS", "SCS", lambda eps: {
            "eps_abs": eps, "eps_rel": eps, "max_iters": 200_000}, "ADMM (conic)"),
    )
}
"""Every solver the package knows; :func:`available_solvers` lists those installed."""


@cache
def _installed_in_cvxpy() -> frozenset[str]:
    """Solvers cvxpy reports installed; asked once, as it costs about 1 ms a call."""
    return frozenset(cp.installed_solvers())


def available_solvers() -> list[str]:
    """Registry names of the solvers installed in this environment."""
    installed = _installed_in_cvxpy()
    return [name for name, spec in SOLVERS.items() if spec.cvxpy_name in installed]


def get_solver(name: str) -> SolverSpec:
    """A solver by name, case-insensitive; :class:`InputError` lists the available ones."""
    key = name.strip().upper()
    available = available_solvers()
    if key not in SOLVERS or key not in available:
        why = "not installed" if key in SOLVERS else "unknown solver"
        raise InputError(f"{why} '{name}' (available: {', '.join(available)})", field="solver")
    return SOLVERS[key]


def tolerance_value(tol: str | float) -> float:
    """``eps`` for a preset name or a positive number."""
    if isinstance(tol, str):
        key = tol.strip().lower()
        if key in TOLERANCE_PRESETS:
            return TOLERANCE_PRESETS[key]
        try:
            tol = float(key)
        except ValueError:
            raise InputError(
                f"unknown tolerance '{tol}' (presets: {', '.join(TOLERANCE_PRESETS)}, "
                "or a positive number)", field="tol") from None
    value = float(tol)
    if not (value > 0.0 and value < 1.0):
        raise InputError(f"tolerance must be in (0, 1), got {tol}", field="tol")
    return value


def solver_options(solver: str, tol: str | float) -> dict[str, Any]:
    """The options dictionary for ``solver`` at tolerance ``tol``."""
    return get_solver(solver).options(tolerance_value(tol))
