"""The solver registry and the one place where tolerances become solver options.

Each :class:`SolverSpec` is everything the package knows about one solver: its name in
cvxpy, its options, the distribution it comes from (and so its version), its colour and
marker in plots, its timing quirks and its adapter (:mod:`wuerfel_cvx.solve.adapters`).

A tolerance is a preset name (``low``, ``default``, ``high``) or a number ``eps``;
:func:`solver_options` maps it to each solver's own option names.  ``high`` is the
tight setting used by the tests and as the reference.
"""

from __future__ import annotations

import importlib.util
import math
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import numpy as np

from ..errors import InputError
from ..versions import package_version

TOLERANCE_PRESETS: dict[str, float] = {"low": 1e-4, "default": 1e-7, "high": 1e-9}
"""Solver tolerance ``eps`` per preset (absolute and relative, in the QP's scaled units)."""


CERTIFICATE_TOLERANCE = float(np.finfo(np.float64).eps)
"""PROXQP's ``eps_dual_inf``: a certificate of dual infeasibility must hold to round-off,
whatever the tolerance of the solve (the step QP's Hessian is positive definite, so none
holds).  At any looser value measured (the step's ``eps``, and 1e-4 to 1e-13) proxsuite 0.8
certified strictly feasible step QPs primal infeasible (``docs/false-infeasible.md``)."""

NO_PRIMAL_CERTIFICATE = -1.0
"""PROXQP's ``eps_primal_inf``: below zero, so that no claim of primal infeasibility passes
proxsuite's test (its right-hand side is this tolerance times a norm).  That test (0.7.2 and
0.8.0, dense and sparse ``global_primal_residual_infeasibility``) adds ``-l' min(dz, 0)``
where Farkas' lemma has ``+l' min(dz, 0)``: with a one-sided row's ``l = -1e20``, any
negative entry of the dual step ``dz`` passes it once ``C' dz`` is round-off, and a resting
contact's twin rows let ``dz`` drift along the null space of ``C'`` until it is.  So
proxsuite certified QPs infeasible that ``x = 0`` satisfies strictly, at any tolerance down
to round-off (``docs/solver-failures.md``).  A truly infeasible QP now runs to
``max_iter``: a failed step with status ``user_limit``."""


@cache
def _osqp_polish_option() -> str:
    """OSQP 1.0 renamed ``polish`` to ``polishing``."""
    try:
        major = int(package_version("osqp").split(".")[0])
    except ValueError:  # not installed, or no version: the current name
        return "polishing"
    return "polishing" if major >= 1 else "polish"


@dataclass(frozen=True)
class Timing:
    """How a solver's own time per solve (s) is read from what it reports."""

    capped_by_native_wall: bool = True
    """On the native path, take the smaller of the report and the wall time of the
    solver's own update and solve calls (one clock with the whole step's; Clarabel's own
    clock reads above the wall time of the very call it times)."""
    zero_is_unknown: bool = True
    """A report of zero or less means "not measured" (cvxpy reports 0.0 for PROXQP)."""
    note: str = ""
    """What is known about this solver's clock, for reports."""

    def solver_time(self, reported: float, native_wall: float | None = None) -> float:
        """The solver's own time (s); NaN when unknown.

        From its ``reported`` time and, on the native path, the ``native_wall`` time of its
        own calls.
        """
        seconds = reported
        if native_wall is not None and self.capped_by_native_wall:
            seconds = min(native_wall, reported)
        if self.zero_is_unknown and not seconds > 0.0:
            return math.nan
        return float(seconds)


@dataclass(frozen=True)
class SolverSpec:
    """Everything about one solver: how to call it, where it comes from, how to show it."""

    name: str
    """Registry name (upper case)."""
    cvxpy_name: str
    """Name of the solver in cvxpy."""
    options: Callable[[float], dict[str, Any]]
    """Solver options for tolerance ``eps``."""
    kind: str
    """``"interior-point"``, ``"ADMM"``, ``"proximal"``... for reports."""
    package: str
    """The distribution that installs it (its version is the solver's)."""
    style: tuple[str, str]
    """Colour (hex) and matplotlib marker, the same in every plot."""
    timing: Timing = field(default_factory=Timing)
    """How its own time is read."""
    adapter: str | None = None
    """Module of :mod:`wuerfel_cvx.solve.adapters` that hands it the step QP's own numbers (the
    ``native`` path; ``None``: it is reached through cvxpy only)."""
    native_only: bool = False
    """Whether it takes its adapter on every path: cvxpy's interface to it does not pose
    the same problem (it drops settings, or adds a regularisation)."""
    takes_warm_start: bool = False
    """Whether its adapter starts from a guess of the last step's solution
    (:mod:`wuerfel_cvx.solve.warm_start`); for the others none is mapped or kept."""

    def version(self) -> str:
        """Installed version of :attr:`package` (``"not installed"``, ``"unknown"``)."""
        return package_version(self.package)


HIGHS_TIME_LIMIT = 60.0
"""Wall seconds HiGHS may spend on one QP.  Its QP solver can cycle without end: rain-10 at
dt 0.02 s, tol ``low``, unpolished, step 95 (highspy 1.16) ran 15 minutes at full load inside
one solve, where a grid point's own time limit (checked between steps) cannot stop it.  With
this limit the step fails with HiGHS's status ``user_limit``, reported with its step."""


@cache
def _quiet_highs() -> dict[str, Any]:
    """No options; HiGHS's banner swallowed, once per process, before any solve.

    The first ``highspy.Highs()`` of a process prints "Running HiGHS ..." to standard
    output whatever its options say; it is created here with file descriptor 1 on
    ``os.devnull`` (the C++ library writes there, not to ``sys.stdout``).
    """
    try:
        import highspy
    except ImportError:  # not installed: nothing to silence
        return {}
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except OSError:  # no standard output to keep clean
        return {}
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            highspy.Highs()  # type: ignore[no-untyped-call]
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    return {}


SOLVERS: dict[str, SolverSpec] = {
    spec.name: spec
    for spec in (
        # One thread, as every other solver here runs: Clarabel's default (all cores) starts
        # a thread pool (rayon, for faer's parallel LDL) at its first solve, and a process
        # forked after it (a sweep's --jobs worker) inherits the pool without its threads:
        # its first factorization large enough to go parallel waited forever (the friction
        # suite's 5050-box pyramid hung a --jobs 2 sweep at 0 % CPU).
        SolverSpec("CLARABEL", "CLARABEL", lambda eps: {
            "tol_gap_abs": eps, "tol_gap_rel": eps, "tol_feas": eps, "tol_ktratio": eps,
            "max_iter": 200, "max_threads": 1}, "interior-point", "clarabel", ("#1f77b4", "o"),
            Timing(note="its solve_time reads above the wall time of the call it times"),
            adapter="clarabel"),
        # OSQP re-estimates its step size rho every 50 iterations from the ratio of its
        # residuals, and takes the estimate only when it is off by more than
        # adaptive_rho_tolerance (OSQP's default 5). Near-parallel rows a hair apart (a
        # resting contact's rate and closest-approach rows, a thin card's two corners on
        # one face) hold its residuals level for thousands of iterations between updates;
        # at 2 the card house's Coulomb steps took 40 % fewer iterations and none of 13
        # other runs took more (reports/perf/coulomb-card-house.md).
        SolverSpec("OSQP", "OSQP", lambda eps: {
            "eps_abs": eps, "eps_rel": eps, _osqp_polish_option(): True, "max_iter": 200_000,
            "adaptive_rho_tolerance": 2.0},
            "ADMM", "osqp", ("#ff7f0e", "s"),
            Timing(note="its run_time includes the data update on the native path"),
            adapter="osqp"),
        SolverSpec("PIQP", "PIQP", lambda eps: {
            "eps_abs": eps, "eps_rel": eps, "max_iter": 250, "compute_timings": True},
            "proximal interior-point", "piqp", ("#2ca02c", "^"),
            Timing(note="its run_time includes the data update on the native path"),
            adapter="piqp"),
        # Native on every path (backends/proxqp.py): cvxpy (1.9) drops the infeasibility
        # tolerances, whose default 1e-4 let PROXQP certify feasible QPs infeasible.
        SolverSpec("PROXQP", "PROXQP", lambda eps: {
            "eps_abs": eps, "eps_rel": 0.0, "max_iter": 10_000,
            "eps_primal_inf": NO_PRIMAL_CERTIFICATE, "eps_dual_inf": CERTIFICATE_TOLERANCE},
            "proximal augmented Lagrangian (dense backend)", "proxsuite", ("#d62728", "D"),
            adapter="proxqp", native_only=True, takes_warm_start=True,
            timing=Timing(note="its run_time includes its setup (a fresh solver per QP)")),
        SolverSpec("SCS", "SCS", lambda eps: {
            "eps_abs": eps, "eps_rel": eps, "max_iters": 200_000}, "ADMM (conic)", "scs",
            ("#9467bd", "v")),
        # Native on every path (backends/daqp.py), on the step QP's own positive-definite
        # Hessian: through cvxpy it sees auxiliary variables without cost and regularises.
        # The friction problem's slacks have no weight: DAQP's proximal-point iterations
        # then solve it, to eps (eta_prox, default 1e-6, left friction impulses 1e-4 off).
        SolverSpec("DAQP", "DAQP", lambda eps: {"primal_tol": eps, "iter_limit": 10_000,
                                                "eta_prox": eps},
                   "dual active-set (dense)", "daqp", ("#8c564b", "P"), adapter="daqp",
                   native_only=True, takes_warm_start=True,
                   timing=Timing(note="its setup_time plus solve_time (dense form built before)")),
        # HiGHS drops matrix entries below small_matrix_value (default 1e-9) from the
        # model; 1e-12 is the floor of that option's range, so only round-off is dropped.
        # Its QP solver adds qp_regularization_value (default 1e-7) to the Hessian's
        # diagonal and so answers another QP: x off by about 1e-7 |x| / w, duals missing
        # stationarity by as much (docs/solver-failures.md). The step QP's own Hessian
        # is positive definite; the friction problem's zero-weight slacks have a linear
        # cost and bounded rows. Native on every path (adapters/highs.py): cvxpy's form
        # turns the targets into right-hand sides, which HiGHS's QP start rounds away.
        SolverSpec("HIGHS", "HIGHS", lambda eps: _quiet_highs() | {
            "primal_feasibility_tolerance": eps, "dual_feasibility_tolerance": eps,
            "small_matrix_value": 1e-12, "qp_regularization_value": 0.0,
            "output_flag": False, "time_limit": HIGHS_TIME_LIMIT}, "active-set (QP)",
            "highspy", ("#e377c2", "X"), adapter="highs", native_only=True),
    )
}
"""Every solver the package knows; :func:`available_solvers` lists those installed."""


@cache
def _installed_in_cvxpy() -> frozenset[str]:
    """Solvers cvxpy reports installed; asked once, as cvxpy probes every solver each call."""
    import cvxpy as cp

    return frozenset(cp.installed_solvers())


@cache
def _installed(name: str) -> bool:
    """Whether the solver ``name`` (a registry key) is installed.

    A solver with an adapter: its module (named as its distribution, :attr:`SolverSpec.package`)
    can be found, as cvxpy finds it, without importing cvxpy (which takes a second: the
    ``native`` path never needs it); any other: cvxpy lists it.
    """
    spec = SOLVERS[name]
    if spec.adapter is not None:
        return importlib.util.find_spec(spec.package) is not None
    return spec.cvxpy_name in _installed_in_cvxpy()


def available_solvers() -> list[str]:
    """Registry names of the solvers installed in this environment."""
    return [name for name in SOLVERS if _installed(name)]


def get_solver(name: str) -> SolverSpec:
    """A solver by name, case-insensitive; :class:`InputError` lists the available ones."""
    key = name.strip().upper()
    if key in SOLVERS and _installed(key):
        return SOLVERS[key]
    why = "not installed" if key in SOLVERS else "unknown solver"
    raise InputError(f"{why} '{name}' (available: {', '.join(available_solvers())})",
                     field="solver")


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
