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
The duals of our rows ``E x = e`` and ``G x >= h`` are read from the solver's by the row
and coefficient each right-hand side takes in the conic data (:class:`ParameterMap`), so
every step is checked by the same independent KKT residuals as any other solve.  The map
uses cvxpy internals (the cached ``ParamConeProg`` and its reduced tensor);
:func:`direct_osqp` and :func:`direct_clarabel` return ``None`` when they do not look as
expected, and the caller falls back to
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
    """cvxpy's status name for the solver's status."""
    solver_time: float
    """The solver's own run time (s)."""
    iterations: int


@dataclass(frozen=True)
class ParameterMap:
    """cvxpy's map from a step QP's numbers to one compiled structure's conic data.

    The conic data are ``A_cone x + b_cone`` in cvxpy's cones; its nonzeros (offset column
    ``b_cone`` last) are ``reduced_map @ vector``, laid out as the CSC pattern
    ``(indices, indptr, shape)``.  Each of our right-hand sides (``e_i``, ``h_i``) enters
    that offset column once, in row ``rows[i]`` with coefficient ``c_i``: the cone row reads
    ``kappa (row . x - rhs)`` with ``kappa = -c_i``.
    """

    slots: tuple[tuple[int, int, str], ...]
    """(start, size, source) of each parameter in the parameter vector."""
    vector_size: int
    reduced_map: sp.csr_array
    q_map: sp.csr_array
    indices: np.ndarray
    indptr: np.ndarray
    shape: tuple[int, int]
    x_offset: int
    eq_rows: np.ndarray
    eq_coefficient: FloatArray
    ineq_rows: np.ndarray
    ineq_coefficient: FloatArray

    def values(self, qp: StepQP) -> tuple[FloatArray, FloatArray]:
        """Nonzeros of the conic data and the linear cost ``q`` for ``qp``'s numbers."""
        vector = np.zeros(self.vector_size)
        vector[-1] = 1.0  # the constant column
        sources = {"weighted_target": np.sqrt(qp.weights) * qp.target,
                   "eq_values": qp.eq_matrix.data, "eq_rhs": qp.eq_rhs,
                   "ineq_values": qp.ineq_matrix.data, "ineq_rhs": qp.ineq_rhs}
        for start, size, source in self.slots:
            vector[start:start + size] = sources[source]
        return self.reduced_map @ vector, np.asarray(self.q_map @ vector).ravel()[:-1]

    @property
    def n_matrix_entries(self) -> int:
        """Nonzeros of ``A_cone`` (those of the offset column follow them)."""
        return int(self.indptr[-2])

    def primal(self, solution: FloatArray, qp: StepQP) -> FloatArray:
        """Our unknowns ``x`` from the solver's primal vector."""
        return np.asarray(solution, dtype=np.float64)[self.x_offset:self.x_offset
                                                      + qp.n_variables]


@dataclass
class DirectOSQP:
    """A structure's parameter map and its persistent OSQP solver.

    OSQP takes cvxpy's rows as ``l <= [A_eq; -A_ineq] x <= u``; a multiplier ``y`` of a
    row with coefficient ``c`` is ``-c y`` in our sign convention (both row kinds).
    """

    mapping: ParameterMap
    ax_index: np.ndarray
    ax_sign: FloatArray
    b_index: np.ndarray
    has_b: np.ndarray
    n_eq_rows: int
    solver: Any
    settings: dict[str, Any]

    def solve(self, qp: StepQP, settings: dict[str, Any]) -> DirectResult:
        """Solve ``qp`` (this structure) with OSQP ``settings``."""
        from cvxpy.reductions.solvers.qp_solvers.osqp_qpif import OSQP as CvxpyOSQP

        values, q = self.mapping.values(qp)
        b_cone = np.where(self.has_b, values[self.b_index], 0.0)
        n_eq = self.n_eq_rows
        lower = np.concatenate([-b_cone[:n_eq], np.full(b_cone.shape[0] - n_eq, -np.inf)])
        upper = np.concatenate([-b_cone[:n_eq], b_cone[n_eq:]])
        osqp_settings = _osqp_settings(settings)
        if osqp_settings != self.settings:
            self.solver.update_settings(**osqp_settings)
            self.settings = osqp_settings
        self.solver.update(q=q, l=lower, u=upper, Ax=self.ax_sign * values[self.ax_index])
        result = self.solver.solve(raise_error=False)
        y = np.asarray(result.y, dtype=np.float64)
        m = self.mapping
        return DirectResult(
            x=m.primal(result.x, qp), eq_dual=-m.eq_coefficient * y[m.eq_rows],
            ineq_dual=-m.ineq_coefficient * y[m.ineq_rows],
            status=str(CvxpyOSQP.STATUS_MAP.get(result.info.status_val, cp.SOLVER_ERROR)),
            solver_time=float(result.info.run_time), iterations=int(result.info.iter))


@dataclass
class DirectClarabel:
    """A structure's parameter map and its persistent Clarabel solver.

    Clarabel takes cvxpy's conic data as ``A = -A_cone``, ``b = b_cone``; a multiplier
    ``z`` of a row with coefficient ``c`` is ``c z`` for an equality and ``-c z`` for an
    inequality in our sign convention.
    """

    mapping: ParameterMap
    b_rows: np.ndarray
    solver: Any

    def solve(self, qp: StepQP, settings: dict[str, Any]) -> DirectResult:
        """Solve ``qp`` (this structure); ``settings`` were fixed when it was set up."""
        from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import CLARABEL

        m = self.mapping
        values, q = m.values(qp)
        count = m.n_matrix_entries
        a = sp.csc_matrix((-values[:count], m.indices[:count], m.indptr[:-1]),
                          shape=(m.shape[0], m.shape[1] - 1))
        b = np.zeros(m.shape[0])
        b[self.b_rows] = values[count:]
        self.solver.update(q=q, b=b, A=a)
        result = self.solver.solve()
        z = np.asarray(result.z, dtype=np.float64)
        return DirectResult(
            x=m.primal(result.x, qp), eq_dual=m.eq_coefficient * z[m.eq_rows],
            ineq_dual=-m.ineq_coefficient * z[m.ineq_rows],
            status=str(CLARABEL.STATUS_MAP.get(str(result.status), cp.SOLVER_ERROR)),
            solver_time=float(result.solve_time), iterations=int(result.iterations))


def direct_osqp(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                options: dict[str, Any]) -> DirectOSQP | None:
    """Set up the direct OSQP path for a compiled ``problem`` whose parameters hold ``qp``.

    ``names`` maps our parameter ids to ``weighted_target``, ``eq_values``, ``eq_rhs``,
    ``ineq_values``, ``ineq_rhs``.  Returns ``None`` if cvxpy's internals are not as
    expected (the caller then keeps using ``Problem.solve()``).
    """
    try:
        return _build_osqp(problem, names, qp, options)
    except Exception:  # any surprise in cvxpy's internals: use the public path instead
        return None


def direct_clarabel(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                    options: dict[str, Any]) -> DirectClarabel | None:
    """As :func:`direct_osqp`, for Clarabel; ``None`` if the path does not apply."""
    try:
        return _build_clarabel(problem, names, qp, options)
    except Exception:  # any surprise in cvxpy's internals: use the public path instead
        return None


def _osqp_settings(options: dict[str, Any]) -> dict[str, Any]:
    settings = {key: value for key, value in options.items() if key not in _NOT_OSQP_SETTINGS}
    settings["warm_starting"] = bool(options.get("warm_start", True))
    settings["verbose"] = False
    return settings


def _build_osqp(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                options: dict[str, Any]) -> DirectOSQP | None:
    import osqp

    built = _parameter_map(problem, names, qp, cp.OSQP)
    if built is None:
        return None
    mapping, data = built
    # OSQP's A stacks cvxpy's equality rows A and inequality rows F = -A_ineq; tag every
    # nonzero of the conic data to find where it lands.
    n_eq = int(data["n_eq"])
    tags = sp.csc_array((np.arange(1.0, len(mapping.indices) + 1), mapping.indices,
                         mapping.indptr), shape=mapping.shape)
    stacked = sp.vstack([tags[:, :-1][:n_eq], -tags[:, :-1][n_eq:]]).tocsc()
    stacked.sort_indices()
    reference = sp.vstack([data["A"], data["F"]]).tocsc()
    reference.sort_indices()
    if not (np.array_equal(reference.indptr, stacked.indptr)
            and np.array_equal(reference.indices, stacked.indices)):
        return None
    b_tags = tags[:, [-1]].toarray().ravel()
    settings = _osqp_settings(options)
    direct = DirectOSQP(mapping=mapping, ax_index=np.abs(stacked.data).astype(np.int64) - 1,
                        ax_sign=np.sign(stacked.data),
                        b_index=np.abs(b_tags).astype(np.int64) - 1, has_b=b_tags != 0,
                        n_eq_rows=n_eq, solver=osqp.OSQP(), settings=settings)
    values, _ = mapping.values(qp)  # must reproduce the data cvxpy just formatted
    if not np.allclose(direct.ax_sign * values[direct.ax_index], reference.data, rtol=0,
                       atol=1e-12):
        return None
    direct.solver.setup(P=sp.csc_matrix(sp.triu(data["P"], format="csc")), q=data["q"],
                        A=sp.csc_matrix(reference),
                        l=np.concatenate([data["b"], np.full(data["G"].shape[0], -np.inf)]),
                        u=np.concatenate([data["b"], data["G"]]), **settings)
    return direct


def _build_clarabel(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                    options: dict[str, Any]) -> DirectClarabel | None:
    import clarabel
    from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import (
        CLARABEL,
        dims_to_solver_cones,
    )

    built = _parameter_map(problem, names, qp, cp.CLARABEL)
    if built is None:
        return None
    mapping, data = built
    count = mapping.n_matrix_entries
    values, _ = mapping.values(qp)  # must reproduce the data cvxpy just formatted
    ours = sp.csc_array((-values[:count], mapping.indices[:count], mapping.indptr[:-1]),
                        shape=(mapping.shape[0], mapping.shape[1] - 1))
    reference = sp.csc_array(data["A"])
    reference.sort_indices()
    if not (np.array_equal(reference.indptr, ours.indptr)
            and np.array_equal(reference.indices, ours.indices)
            and np.allclose(reference.data, ours.data, rtol=0, atol=1e-12)):
        return None
    solver = clarabel.DefaultSolver(sp.csc_matrix(sp.triu(data["P"]).tocsc()), data["c"],
                                    sp.csc_matrix(reference), data["b"],
                                    dims_to_solver_cones(data["dims"]),
                                    CLARABEL().parse_solver_opts(False, dict(options)))
    if not solver.is_data_update_allowed():
        return None
    return DirectClarabel(mapping=mapping, b_rows=np.asarray(mapping.indices[count:]),
                          solver=solver)


def _parameter_map(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                   solver: str) -> tuple[ParameterMap, dict[str, Any]] | None:
    """Compile ``problem`` for ``solver`` and read cvxpy's parameter map off its program."""
    with warnings.catch_warnings():  # cvxpy reads its own sparse parameters densely
        warnings.filterwarnings("ignore", "Reading from a sparse CVXPY expression",
                                RuntimeWarning)
        data, chain, _ = problem.get_problem_data(solver)
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
    tensor = program.reduced_A
    tensor.cache(keep_zeros=True)
    indices, indptr, shape = tensor.problem_data_index
    reduced_map = sp.csr_array(tensor.reduced_mat)
    offset_entries = (int(indptr[-2]), int(indptr[-1]))
    eq = _rhs_rows(reduced_map, indices, offset_entries, slots, "eq_rhs", qp.n_equalities)
    ineq = _rhs_rows(reduced_map, indices, offset_entries, slots, "ineq_rhs",
                     qp.n_inequalities)
    if eq is None or ineq is None:
        return None
    mapping = ParameterMap(
        slots=tuple(slots), vector_size=int(program.total_param_size) + 1,
        reduced_map=reduced_map, q_map=sp.csr_array(program.q), indices=np.asarray(indices),
        indptr=np.asarray(indptr), shape=(int(shape[0]), int(shape[1])),
        x_offset=int(program.var_id_to_col[problem.variables()[0].id]),
        eq_rows=eq[0], eq_coefficient=eq[1], ineq_rows=ineq[0], ineq_coefficient=ineq[1])
    return mapping, data


def _rhs_rows(reduced_map: sp.csr_array, indices: np.ndarray, offset_entries: tuple[int, int],
              slots: list[tuple[int, int, str]], source: str,
              count: int) -> tuple[np.ndarray, FloatArray] | None:
    """Conic row and coefficient of each of our right-hand sides ``source`` (``count``).

    Each must enter the conic data exactly once, in the offset column.
    """
    if count == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    start = next((s for s, size, name in slots if name == source and size == count), None)
    if start is None:
        return None
    columns = sp.csc_array(reduced_map[:, start:start + count])
    first, last = offset_entries
    rows, coefficients = np.zeros(count, np.int64), np.zeros(count)
    for j in range(count):
        entries = columns.indices[columns.indptr[j]:columns.indptr[j + 1]]
        if entries.size != 1 or not first <= entries[0] < last:
            return None
        rows[j] = indices[entries[0]]
        coefficients[j] = columns.data[columns.indptr[j]]
    return rows, coefficients
