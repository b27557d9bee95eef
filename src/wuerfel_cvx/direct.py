"""The direct path: cvxpy's parameter map applied by hand, one persistent solver per structure.

A compiled step problem (:mod:`wuerfel_cvx.compiled`) re-solved through ``Problem.solve()``
still pays cvxpy's per-call work: validating parameter values, applying the parameter map
through scipy constructors, creating a new native solver and unpacking the result
(1.5-3 ms a step, several times OSQP's own time on a 50-square stack).  Here, once per
structure, cvxpy compiles the problem (``get_problem_data``); its parametric program holds
the linear map from the parameter vector to the solver's data.  Each step then

1. fills the parameter vector from the step QP's numbers (``sqrt(w) t``, the nonzeros of
   ``E`` and ``G`` in their canonical order, ``e``, ``h``),
2. multiplies it by cvxpy's own reduced map, giving the nonzeros of the conic data,
3. scatters them into the solver's data by index maps found once (OSQP: ``q``, ``l``,
   ``u``, ``A``; Clarabel: ``q``, ``b``, ``A``), and
4. updates a persistent ``osqp.OSQP`` or ``clarabel.DefaultSolver`` in place and solves.

The model is the cvxpy one: no matrix is written by hand, only cvxpy's map is applied.
The duals of our rows ``E x = e`` and ``G x >= h`` are read from OSQP's by the row and sign
each right-hand side takes in the conic data, so every step is checked by the same
independent KKT residuals as any other solve.  The map uses cvxpy internals (the cached
``ParamConeProg`` and its reduced tensor); :func:`direct_osqp` and :func:`direct_clarabel`
return ``None`` when they do not look as expected, and the caller falls back to
``Problem.solve()``.  PIQP, PROXQP and SCS always go through ``Problem.solve()``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from .formulations.qp import StepQP
from .geometry import FloatArray

_NOT_OSQP_SETTINGS = {"warm_start"}


@dataclass(frozen=True)
class DirectResult:
    """A direct solve: primal, the duals of our rows, and the solver's report."""

    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    status: str
    """cvxpy's status name for OSQP's status."""
    solver_time: float
    """OSQP's own run time (s)."""
    iterations: int


@dataclass
class DirectOSQP:
    """One structure's parameter map and its persistent OSQP solver."""

    parameter_slots: list[tuple[int, int, str]]
    """(start, size, source) of each parameter in the parameter vector."""
    vector_size: int
    reduced_map: sp.csr_array
    ax_index: np.ndarray
    ax_sign: FloatArray
    b_index: np.ndarray
    has_b: np.ndarray
    n_eq_rows: int
    q_map: sp.csr_array
    x_offset: int
    eq_rows: np.ndarray
    eq_sign: FloatArray
    ineq_rows: np.ndarray
    ineq_sign: FloatArray
    solver: Any
    settings: dict[str, Any]

    def solve(self, qp: StepQP, settings: dict[str, Any]) -> DirectResult:
        """Solve ``qp`` (this structure) with OSQP ``settings``."""
        from cvxpy.reductions.solvers.qp_solvers.osqp_qpif import OSQP as CvxpyOSQP

        vector = self._parameter_vector(qp)
        values = self.reduced_map @ vector
        b_cone = np.where(self.has_b, values[self.b_index], 0.0)
        n_rows = b_cone.shape[0]
        lower = np.concatenate([-b_cone[: self.n_eq_rows],
                                np.full(n_rows - self.n_eq_rows, -np.inf)])
        upper = np.concatenate([-b_cone[: self.n_eq_rows], b_cone[self.n_eq_rows:]])
        q = np.asarray(self.q_map @ vector).ravel()[:-1]
        osqp_settings = _osqp_settings(settings)
        if osqp_settings != self.settings:
            self.solver.update_settings(**osqp_settings)
            self.settings = osqp_settings
        self.solver.update(q=q, l=lower, u=upper, Ax=self.ax_sign * values[self.ax_index])
        result = self.solver.solve(raise_error=False)
        status = CvxpyOSQP.STATUS_MAP.get(result.info.status_val, cp.SOLVER_ERROR)
        x = np.asarray(result.x, dtype=np.float64)[self.x_offset:self.x_offset
                                                   + qp.n_variables]
        y = np.asarray(result.y, dtype=np.float64)
        return DirectResult(x=x, eq_dual=self.eq_sign * y[self.eq_rows],
                            ineq_dual=self.ineq_sign * y[self.ineq_rows], status=str(status),
                            solver_time=float(result.info.run_time),
                            iterations=int(result.info.iter))

    def _parameter_vector(self, qp: StepQP) -> FloatArray:
        vector = np.zeros(self.vector_size)
        vector[-1] = 1.0  # the constant column
        sources = {"weighted_target": np.sqrt(qp.weights) * qp.target,
                   "eq_values": qp.eq_matrix.data, "eq_rhs": qp.eq_rhs,
                   "ineq_values": qp.ineq_matrix.data, "ineq_rhs": qp.ineq_rhs}
        for start, size, source in self.parameter_slots:
            vector[start:start + size] = sources[source]
        return vector


@dataclass
class DirectClarabel:
    """One structure's parameter map and its persistent Clarabel solver.

    Clarabel takes cvxpy's conic data as ``A = -A_cone``, ``b = b_cone``; its dual ``z``
    gives our multipliers with the signs of :func:`_rhs_rows` (equalities negated).
    """

    osqp_like: DirectOSQP
    """The shared parameter map (its OSQP-specific fields are unused here)."""
    a_count: int
    a_pattern: tuple[np.ndarray, np.ndarray, tuple[int, int]]
    b_rows: np.ndarray
    b_entries: np.ndarray
    n_rows: int
    solver: Any

    def solve(self, qp: StepQP, settings: dict[str, Any]) -> DirectResult:
        """Solve ``qp`` (this structure); ``settings`` were fixed when it was set up."""
        from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import CLARABEL

        base = self.osqp_like
        vector = base._parameter_vector(qp)
        values = base.reduced_map @ vector
        indices, indptr, shape = self.a_pattern
        a = sp.csc_matrix((-values[: self.a_count], indices, indptr), shape=shape)
        b = np.zeros(self.n_rows)
        b[self.b_rows] = values[self.b_entries]
        q = np.asarray(base.q_map @ vector).ravel()[:-1]
        self.solver.update(q=q, b=b, A=a)
        result = self.solver.solve()
        status = CLARABEL.STATUS_MAP.get(str(result.status), cp.SOLVER_ERROR)
        x = np.asarray(result.x, dtype=np.float64)[base.x_offset:base.x_offset
                                                   + qp.n_variables]
        z = np.asarray(result.z, dtype=np.float64)
        return DirectResult(x=x, eq_dual=-base.eq_sign * z[base.eq_rows],
                            ineq_dual=base.ineq_sign * z[base.ineq_rows], status=str(status),
                            solver_time=float(result.solve_time),
                            iterations=int(result.iterations))


def direct_clarabel(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                    options: dict[str, Any]) -> DirectClarabel | None:
    """As :func:`direct_osqp`, for Clarabel; ``None`` if the path does not apply."""
    try:
        return _build_clarabel(problem, names, qp, options)
    except Exception:  # any surprise in cvxpy's internals: use the public path instead
        return None


def _build_clarabel(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                    options: dict[str, Any]) -> DirectClarabel | None:
    import clarabel
    from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import (
        CLARABEL,
        dims_to_solver_cones,
    )

    base = _build(problem, names, qp, options, with_osqp=False)
    if base is None:
        return None
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Reading from a sparse CVXPY expression",
                                RuntimeWarning)
        data, _, _ = problem.get_problem_data(cp.CLARABEL)
    indices, indptr, shape = problem._cache.param_prog.reduced_A.problem_data_index
    a_count = int(indptr[-2])
    a_pattern = (np.asarray(indices[:a_count]), np.asarray(indptr[:-1]),
                 (int(shape[0]), int(shape[1]) - 1))
    reference = sp.csc_array(data["A"])
    reference.sort_indices()
    values = base.reduced_map @ base._parameter_vector(qp)
    ours = sp.csc_array((-values[:a_count], a_pattern[0], a_pattern[1]), shape=a_pattern[2])
    if not (np.array_equal(reference.indptr, ours.indptr)
            and np.array_equal(reference.indices, ours.indices)
            and np.allclose(reference.data, ours.data, rtol=0, atol=1e-12)):
        return None
    b_entries = np.arange(int(indptr[-2]), int(indptr[-1]))
    settings = CLARABEL().parse_solver_opts(False, dict(options))
    solver = clarabel.DefaultSolver(sp.csc_matrix(sp.triu(data["P"]).tocsc()), data["c"],
                                    sp.csc_matrix(reference), data["b"],
                                    dims_to_solver_cones(data["dims"]), settings)
    if not solver.is_data_update_allowed():
        return None
    return DirectClarabel(osqp_like=base, a_count=a_count, a_pattern=a_pattern,
                          b_rows=np.asarray(indices[b_entries]), b_entries=b_entries,
                          n_rows=int(shape[0]), solver=solver)


def _osqp_settings(options: dict[str, Any]) -> dict[str, Any]:
    settings = {key: value for key, value in options.items() if key not in _NOT_OSQP_SETTINGS}
    settings["warm_starting"] = bool(options.get("warm_start", True))
    settings["verbose"] = False
    return settings


def direct_osqp(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                options: dict[str, Any]) -> DirectOSQP | None:
    """Set up the direct path for a compiled ``problem`` whose parameters hold ``qp``.

    ``names`` maps our parameter ids to ``weighted_target``, ``eq_values``, ``eq_rhs``,
    ``ineq_values``, ``ineq_rhs``.  Returns ``None`` if cvxpy's internals are not as
    expected (the caller then keeps using ``Problem.solve()``).
    """
    try:
        return _build(problem, names, qp, options)
    except Exception:  # any surprise in cvxpy's internals: use the public path instead
        return None


def _build(problem: cp.Problem, names: dict[int, str], qp: StepQP,
           options: dict[str, Any], with_osqp: bool = True) -> DirectOSQP | None:
    import osqp

    with warnings.catch_warnings():  # cvxpy reads its own sparse parameters densely
        warnings.filterwarnings("ignore", "Reading from a sparse CVXPY expression",
                                RuntimeWarning)
        data, chain, _ = problem.get_problem_data(cp.OSQP if with_osqp else cp.CLARABEL)
    program = problem._cache.param_prog
    reduced_to_ours = {}
    for reduction in chain.reductions:
        for original, reduced in getattr(reduction, "_parameters", {}).items():
            reduced_to_ours[reduced.id] = original.id
    slots = []
    for param_id, column in program.param_id_to_col.items():
        if param_id == -1:  # cvxpy's constant column
            continue
        ours = reduced_to_ours.get(param_id, param_id)
        if ours not in names:
            return None
        slots.append((int(column), int(program.param_id_to_size[param_id]), names[ours]))
    size = int(program.total_param_size) + 1
    tensor = program.reduced_A
    tensor.cache(keep_zeros=True)
    indices, indptr, shape = tensor.problem_data_index
    tags = sp.csc_array((np.arange(1.0, len(indices) + 1), indices, indptr), shape=shape)
    b_tags = tags[:, [-1]].toarray().ravel()
    if with_osqp:  # OSQP's A stacks cvxpy's equality rows A and inequality rows F = -A_cone
        n_eq = int(data["n_eq"])
        stacked = sp.vstack([tags[:, :-1][:n_eq], -tags[:, :-1][n_eq:]]).tocsc()
        stacked.sort_indices()
        reference = sp.vstack([data["A"], data["F"]]).tocsc()
        reference.sort_indices()
        if not (np.array_equal(reference.indptr, stacked.indptr)
                and np.array_equal(reference.indices, stacked.indices)):
            return None
    else:  # Clarabel takes A = -A_cone whole; its builder checks that separately
        n_eq = 0
        stacked = reference = sp.csc_array((0, 0))
    direct = DirectOSQP(
        parameter_slots=slots, vector_size=size, reduced_map=sp.csr_array(tensor.reduced_mat),
        ax_index=np.abs(stacked.data).astype(np.int64) - 1, ax_sign=np.sign(stacked.data),
        b_index=np.abs(b_tags).astype(np.int64) - 1, has_b=b_tags != 0, n_eq_rows=n_eq,
        q_map=sp.csr_array(program.q), x_offset=int(program.var_id_to_col[
            problem.variables()[0].id]),
        eq_rows=np.zeros(0, np.int64), eq_sign=np.zeros(0), ineq_rows=np.zeros(0, np.int64),
        ineq_sign=np.zeros(0), solver=None, settings={})
    eq = _rhs_rows(direct, tags, indptr, slots, "eq_rhs", qp.n_equalities)
    ineq = _rhs_rows(direct, tags, indptr, slots, "ineq_rhs", qp.n_inequalities)
    if eq is None or ineq is None:
        return None
    direct.eq_rows, direct.eq_sign = eq
    direct.ineq_rows, direct.ineq_sign = ineq
    if not with_osqp:
        return direct
    # the conic data at the current values must be the data cvxpy just formatted
    values = direct.reduced_map @ direct._parameter_vector(qp)
    if not np.allclose(direct.ax_sign * values[direct.ax_index], reference.data, rtol=0,
                       atol=1e-12):
        return None
    direct.settings = _osqp_settings(options)
    direct.solver = osqp.OSQP()
    direct.solver.setup(P=sp.csc_matrix(sp.triu(data["P"], format="csc")), q=data["q"],
                        A=sp.csc_matrix(reference),
                        l=np.concatenate([data["b"], np.full(data["G"].shape[0], -np.inf)]),
                        u=np.concatenate([data["b"], data["G"]]), **direct.settings)
    return direct


def _rhs_rows(direct: DirectOSQP, tags: sp.csc_array, indptr: np.ndarray,
              slots: list[tuple[int, int, str]], source: str,
              count: int) -> tuple[np.ndarray, FloatArray] | None:
    """OSQP row and dual sign of each of our right-hand sides ``source`` (``count`` rows).

    A right-hand side enters the conic data only in the offset column, once, with a
    coefficient c: the row reads ``kappa (row . x) - kappa rhs`` with ``kappa = -c``, so
    our multiplier is ``-c`` times OSQP's.
    """
    if count == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    start = next((s for s, size, name in slots if name == source and size == count), None)
    if start is None:
        return None
    columns = sp.csc_array(direct.reduced_map[:, start:start + count])
    offset_entries = np.arange(indptr[-2], indptr[-1])  # data entries of the offset column
    rows, signs = np.zeros(count, np.int64), np.zeros(count)
    entry_rows = tags.indices  # row of every data entry
    for j in range(count):
        entries = columns.indices[columns.indptr[j]:columns.indptr[j + 1]]
        coefficients = columns.data[columns.indptr[j]:columns.indptr[j + 1]]
        in_offset = np.isin(entries, offset_entries)
        if in_offset.sum() != 1 or (~in_offset).any():
            return None
        rows[j] = entry_rows[entries[in_offset][0]]
        signs[j] = -coefficients[in_offset][0]
    return rows, signs
