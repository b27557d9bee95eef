"""PROXQP's native backend: proxsuite called on the step QP's own numbers, on every path.

cvxpy's PROXQP interface (1.9) forwards only a few of proxsuite's settings and drops the
others silently, among them ``eps_primal_inf`` and ``eps_dual_inf``: the tolerances of
proxsuite's infeasibility certificates, which default to 1e-4 whatever ``eps_abs`` is.
This backend therefore does not go through cvxpy at all, on the first QP of a structure,
on compiled structures and with ``compiled=False`` alike
(:attr:`~wuerfel_cvx.solve.registry.SolverSpec.native`); the registry sets the certificates'
tolerances (:data:`~wuerfel_cvx.solve.registry.CERTIFICATE_TOLERANCE`; the primal one below
zero, :data:`~wuerfel_cvx.solve.registry.NO_PRIMAL_CERTIFICATE`, as proxsuite's test of it has
a sign wrong).  It hands proxsuite's dense
backend the QP in proxsuite's form ``min x' H x / 2 + g' x``, ``A x = b``, ``l <= C x <= u`` with

    H = 2 W + 2 F' F,   g = -H t + l,   A = E,   b = e,

and, per row of ``G``: ``-G_i x <= -h_i`` (``l_i = -inf``) for a one-sided row, as cvxpy
passes it, and ``h_i <= G_i x <= u_i`` for a row with a finite upper bound.  One-sided rows
are not given as ``h_i <= G_i x <= +inf``: with an infinite upper bound proxsuite 0.8 never
certifies infeasibility (it ran to its iteration limit on a truly infeasible QP, see
``docs/false-infeasible.md``; the sign error of its test, which the registry now switches
off, turns a true certificate on a lower bound into a rejected one).  The objective is the
step QP's without its constant (proxsuite takes none; with ``eps_rel = 0`` its stopping
test is absolute, so the constant would not enter it).  proxsuite's Lagrangian is
``H x + g + A' y + C' z = 0``; so ``y`` is the package's, and the package's
``z = z_lower - z_upper`` (:mod:`wuerfel_cvx.formulations.qp`) is ``z`` on a negated row and
``-z`` on a two-sided one.

The dense backend is used, as cvxpy uses it.  The sparse one (its default Cholesky
backend) did not return on a step QP of ``stack-10`` that the dense one solves in 4
iterations, with any of the iteration limits tried; its matrix-free backend was 13 to 44
times slower and did not return on another.  The dense AVX-512 build's round-off depends on where
its arrays lie in memory, so its answers can differ in the last bits between processes and
between calls (``docs/false-infeasible.md``); that is proxsuite's, and aligning the inputs
does not remove it (the solver's own buffers count too).  A fresh solver is set up for
every QP; a warm start from the last step (:mod:`wuerfel_cvx.solve.warm_start`) is handed
to it as its initial guess.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..._sparse import dense_rows
from ...formulations.qp import StepQP
from ...scenes.geometry import FloatArray
from ..warm_start import WarmStart
from ._native import Accept, Answer, NativeData, status_name

MICROSECOND = 1e-6
"""proxsuite reports its times in microseconds."""

_STATUS = {"PROXQP_SOLVED": "optimal", "PROXQP_MAX_ITER_REACHED": "user_limit",
           "PROXQP_PRIMAL_INFEASIBLE": "infeasible", "PROXQP_DUAL_INFEASIBLE": "unbounded"}
"""PROXQP's statuses by name (cvxpy's table)."""


def proxsuite_form(qp: StepQP) -> tuple[dict[str, Any], FloatArray]:
    """``qp`` as proxsuite's ``H, g, A, b, C, l, u``, and the sign that maps its ``z`` to ours.

    Dense matrices (the dense backend's input), ``None`` for an empty block.  ``C``'s row
    ``i`` is ``-G_i`` (sign ``+1``) for a one-sided row and ``G_i`` (sign ``-1``) for one
    with a finite upper bound.
    """
    if qp.cost_factor is not None and qp.n_cost_rows:
        factor = sp.csc_array(qp.cost_factor)
        hessian = sp.csc_array(sp.diags_array(2.0 * qp.weights, format="csc")
                               + 2.0 * (factor.T @ factor))
        dense_hessian, linear = hessian.toarray(), -(hessian @ qp.target)
    else:  # 2 W: the sparse product's sums of one term each, 0.0 + 2 w t
        diagonal = 2.0 * qp.weights
        dense_hessian, linear = np.diag(diagonal), -(0.0 + diagonal * qp.target)
    if qp.linear is not None:  # a linear cost l' x
        linear = linear + qp.linear
    sign = np.ones(qp.n_inequalities)
    sign[qp.upper_rows] = -1.0
    lower = np.where(sign > 0, -np.inf, qp.ineq_rhs)
    upper = -qp.ineq_rhs
    if qp.upper_rows.size:
        assert qp.ineq_upper is not None
        upper[qp.upper_rows] = qp.ineq_upper[qp.upper_rows]
    has_eq, has_ineq = qp.n_equalities > 0, qp.n_inequalities > 0
    form = {"H": dense_hessian, "g": linear,
            "A": dense_rows(qp.eq_matrix) if has_eq else None,
            "b": qp.eq_rhs if has_eq else None,
            "C": dense_rows(qp.ineq_matrix, row_factor=-sign) if has_ineq else None,
            "l": lower if has_ineq else None, "u": upper if has_ineq else None}
    return form, sign


def _solve(qp: StepQP, options: dict[str, Any], warm: WarmStart | None = None) -> Answer:
    """Solve ``qp`` with proxsuite's dense backend and ``options`` (proxsuite settings).

    Every option is one of proxsuite's settings, set by name; an unknown name raises
    ``AttributeError`` (a failed step), so that no setting is dropped silently.  With
    ``warm``, proxsuite starts from its primal and multipliers (``WARM_START``).
    """
    import proxsuite  # type: ignore[import-untyped]  # an optional solver, no stubs

    solver = proxsuite.proxqp.dense.QP(qp.n_variables, qp.n_equalities, qp.n_inequalities)
    settings = solver.settings
    for name, value in {**options, "verbose": False, "compute_timings": True}.items():
        if not hasattr(settings, name):
            raise AttributeError(f"proxsuite has no setting '{name}'")
        setattr(settings, name, value)
    form, sign = proxsuite_form(qp)
    started = time.perf_counter()
    solver.init(**form)
    if warm is None:
        solver.solve()
    else:
        settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START
        solver.solve(warm.x, warm.eq_dual, sign * warm.ineq_dual)
    native_time = time.perf_counter() - started
    results = solver.results
    info = results.info
    return Answer(
        x=np.array(results.x, dtype=np.float64),
        eq_dual=np.array(results.y, dtype=np.float64),
        ineq_dual=sign * np.array(results.z, dtype=np.float64),
        status=status_name(_STATUS, info.status.name),
        reported_time=float(info.run_time) * MICROSECOND, native_time=native_time,
        iterations=int(info.iter))


class PROXQPAdapter:
    """PROXQP on a structure's QPs: dense data, set up afresh for every QP."""

    def __init__(self, options: dict[str, Any]):
        # the last step's start comes as ``warm`` (the mapped guess), not as a setting
        self.options = {key: value for key, value in options.items() if key != "warm_start"}

    def solve(self, data: NativeData, warm: WarmStart | None = None,
              accept: Accept | None = None) -> Answer:
        """Solve ``data`` from ``warm`` if given; ``accept`` is ignored (one stage)."""
        return _solve(data.qp, self.options, warm)


def setup(data: NativeData, options: dict[str, Any]) -> PROXQPAdapter:
    """PROXQP for ``data``'s structure with ``options`` (PROXQP settings)."""
    return PROXQPAdapter(options)
