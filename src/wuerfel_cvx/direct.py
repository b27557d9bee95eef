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
3. scatters them into the solver's data by index maps found once (OSQP and PIQP: cvxpy's
   QP form ``A x = b``, ``F x <= g``, :class:`_QPForm`; Clarabel: ``q``, ``b``, ``A``), and
4. updates a persistent ``osqp.OSQP``, ``piqp.SparseSolver`` or ``clarabel.DefaultSolver``
   in place and solves.

The model is the cvxpy one: no matrix is written by hand, only cvxpy's map is applied.
The duals of our rows ``E x = e`` and ``G x >= h`` are read from the solver's by the row
and coefficient each right-hand side takes in the conic data (:class:`ParameterMap`), so
every step is checked by the same independent KKT residuals as any other solve.  The map
uses cvxpy internals (the cached ``ParamConeProg`` and its reduced tensor);
:func:`build_direct` returns ``None`` when they do not look as expected, and the caller
falls back to ``Problem.solve()``.  PROXQP
and SCS always go through ``Problem.solve()``.

The solver time of a direct solve is the smaller of the solver's own report and the wall
time of the native update and solve calls, measured with the same clock as the whole step.
For OSQP and PIQP that is their ``run_time`` (which includes their update on this path): it
reads 7 to 16 % below the wall time of the calls, the rest being their Python bindings'
data transfer (median over stack-20 and stack-50 steps).  Clarabel's ``solve_time`` reads
10 to 16 % *above* the wall time of the very call it times, and up to twice the whole
step's wall time in a benchmark worker sharing the cores (``stack-10``, dt 0.005 s,
``--jobs 2``), which gave step / solver ratios below 1; the wall time is used instead.
Through cvxpy the solver's own report is all there is.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from .formulations.qp import StepQP
from .geometry import FloatArray

_NOT_OSQP_SETTINGS = {"warm_start"}
_NOT_PIQP_SETTINGS = {"warm_start", "backend"}


@dataclass(frozen=True)
class DirectResult:
    """A direct solve: primal, the duals of our rows, and the solver's report."""

    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    status: str
    """cvxpy's status name for the solver's status."""
    solver_time: float
    """The solver's own time (s): the smaller of its report and the wall time of the native
    update and solve calls (see the module docstring)."""
    reported_time: float
    """The time the solver reports for itself (s)."""
    native_time: float
    """Wall time (s) of the native update and solve calls."""
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


@dataclass(frozen=True)
class _Gather:
    """Where the nonzeros of one of a solver's matrices come from in the conic data's.

    Built from the matrix's pattern with every entry a signed tag ``+-(k + 1)``: entry
    ``k`` of the conic data's nonzeros, with that sign.
    """

    tags: sp.csc_array
    index: np.ndarray
    sign: FloatArray
    matrix: sp.csc_matrix
    """The pattern; :meth:`fill` overwrites its values."""

    @classmethod
    def of(cls, tags: sp.sparray) -> _Gather:
        """The gather for a tagged matrix."""
        tagged = sp.csc_array(tags)
        tagged.sort_indices()
        return cls(tags=tagged, index=np.abs(tagged.data).astype(np.int64) - 1,
                   sign=np.sign(tagged.data),
                   matrix=sp.csc_matrix(tagged, dtype=np.float64, copy=True))

    def values(self, nonzeros: FloatArray) -> FloatArray:
        """The matrix's nonzeros (CSC order) from the conic data's."""
        return np.asarray(self.sign * nonzeros[self.index], dtype=np.float64)

    def fill(self, nonzeros: FloatArray) -> sp.csc_matrix:
        """The matrix with the values for ``nonzeros`` (the same object every call)."""
        self.matrix.data[:] = self.values(nonzeros)
        return self.matrix

    def reproduces(self, reference: sp.sparray | sp.spmatrix, nonzeros: FloatArray) -> bool:
        """Whether this gather gives cvxpy's own matrix ``reference`` (pattern and values)."""
        matrix = sp.csc_array(reference)
        matrix.sort_indices()
        return bool(matrix.shape == self.tags.shape
                    and np.array_equal(matrix.indptr, self.tags.indptr)
                    and np.array_equal(matrix.indices, self.tags.indices)
                    and np.allclose(self.values(nonzeros), matrix.data, rtol=0, atol=1e-12))


@dataclass(frozen=True)
class _QPForm:
    """cvxpy's QP form of a structure (as given to OSQP and PIQP), read off its conic data.

    cvxpy's QP solvers take ``min 1/2 x' P x + q' x`` s.t. ``A x = b``, ``F x <= g`` with
    ``A = A_cone[eq]``, ``b = -b_cone[eq]``, ``F = -A_cone[ineq]``, ``g = b_cone[ineq]``
    (the equality rows come first in the conic data).  ``P`` does not depend on the
    parameters (the weights are part of the structure).
    """

    mapping: ParameterMap
    n_eq: int
    b_index: np.ndarray
    has_b: np.ndarray
    eq: _Gather
    """``A`` from the conic data's nonzeros."""
    ineq: _Gather
    """``F`` from the conic data's nonzeros."""

    def rhs(self, nonzeros: FloatArray) -> tuple[FloatArray, FloatArray]:
        """``b`` and ``g`` from the conic data's nonzeros."""
        b_cone = np.where(self.has_b, nonzeros[self.b_index], 0.0)
        return -b_cone[:self.n_eq], b_cone[self.n_eq:]

    def duals(self, eq_multiplier: FloatArray,
              ineq_multiplier: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Our duals from the multipliers ``y`` of ``A x = b`` and ``z`` of ``F x <= g``.

        With the Lagrangian ``P x + q + A' y + F' z = 0`` (OSQP's and PIQP's), the
        multiplier of a row with coefficient ``c`` is ``-c`` times it in our convention.
        """
        m = self.mapping
        return (-m.eq_coefficient * eq_multiplier[m.eq_rows],
                -m.ineq_coefficient * ineq_multiplier[m.ineq_rows - self.n_eq])

    @classmethod
    def of(cls, problem: cp.Problem, names: dict[int, str], qp: StepQP,
           solver: str) -> tuple[_QPForm, dict[str, Any]] | None:
        """Compile ``problem`` for ``solver``; ``None`` unless the maps reproduce its data."""
        built = _parameter_map(problem, names, qp, solver)
        if built is None:
            return None
        mapping, data = built
        n_eq = int(data["n_eq"])
        tags = sp.csc_array((np.arange(1.0, len(mapping.indices) + 1), mapping.indices,
                             mapping.indptr), shape=mapping.shape)
        b_tags = tags[:, [-1]].toarray().ravel()
        form = cls(mapping=mapping, n_eq=n_eq, b_index=np.abs(b_tags).astype(np.int64) - 1,
                   has_b=b_tags != 0, eq=_Gather.of(tags[:, :-1][:n_eq]),
                   ineq=_Gather.of(-tags[:, :-1][n_eq:]))
        values, _ = mapping.values(qp)  # must reproduce the data cvxpy just formatted
        b, g = form.rhs(values)
        if not (form.eq.reproduces(data["A"], values) and form.ineq.reproduces(data["F"], values)
                and np.allclose(b, data["b"], rtol=0, atol=1e-12)
                and np.allclose(g, data["G"], rtol=0, atol=1e-12)):
            return None
        return form, data


@dataclass
class DirectOSQP:
    """A structure's QP form and its persistent OSQP solver.

    OSQP takes cvxpy's QP form as ``l <= [A; F] x <= u``.
    """

    form: _QPForm
    stacked: _Gather
    """``[A; F]`` from the conic data's nonzeros."""
    solver: Any
    settings: dict[str, Any]

    def solve(self, qp: StepQP, settings: dict[str, Any]) -> DirectResult:
        """Solve ``qp`` (this structure) with OSQP ``settings``."""
        from cvxpy.reductions.solvers.qp_solvers.osqp_qpif import OSQP as CvxpyOSQP

        values, q = self.form.mapping.values(qp)
        b, g = self.form.rhs(values)
        lower = np.concatenate([b, np.full(g.shape[0], -np.inf)])
        upper = np.concatenate([b, g])
        osqp_settings = _osqp_settings(settings)
        if osqp_settings != self.settings:
            self.solver.update_settings(**osqp_settings)
            self.settings = osqp_settings
        Ax = self.stacked.values(values)
        started = time.perf_counter()
        self.solver.update(q=q, l=lower, u=upper, Ax=Ax)
        result = self.solver.solve(raise_error=False)
        native_time = time.perf_counter() - started
        y = np.asarray(result.y, dtype=np.float64)
        eq_dual, ineq_dual = self.form.duals(y[:self.form.n_eq], y[self.form.n_eq:])
        return DirectResult(
            x=self.form.mapping.primal(result.x, qp), eq_dual=eq_dual, ineq_dual=ineq_dual,
            status=str(CvxpyOSQP.STATUS_MAP.get(result.info.status_val, cp.SOLVER_ERROR)),
            solver_time=min(native_time, float(result.info.run_time)),
            reported_time=float(result.info.run_time), native_time=native_time,
            iterations=int(result.info.iter))


@dataclass
class DirectPIQP:
    """A structure's QP form and its persistent PIQP (sparse) solver.

    PIQP takes cvxpy's QP form as ``A x = b``, ``F x <= h_u`` (no lower bound, as cvxpy
    passes it).  Its ``run_time``, the time cvxpy reports for PIQP, is the update of the
    data plus the solve here (setup plus solve on a fresh solver); PIQP has no warm start.
    """

    form: _QPForm
    solver: Any
    settings: dict[str, Any]

    def solve(self, qp: StepQP, settings: dict[str, Any]) -> DirectResult:
        """Solve ``qp`` (this structure) with PIQP ``settings``."""
        from cvxpy.reductions.solvers.qp_solvers.piqp_qpif import PIQP as CvxpyPIQP

        form = self.form
        values, q = form.mapping.values(qp)
        b, g = form.rhs(values)
        piqp_settings = _piqp_settings(settings)
        if piqp_settings != self.settings:
            _apply_piqp_settings(self.solver, piqp_settings)
            self.settings = piqp_settings
        data: dict[str, Any] = {"c": q}
        if b.size:
            data |= {"A": form.eq.fill(values), "b": b}
        if g.size:
            data |= {"G": form.ineq.fill(values), "h_u": g}
        started = time.perf_counter()
        self.solver.update(**data)
        self.solver.solve()
        native_time = time.perf_counter() - started
        result = self.solver.result  # its arrays are views the next solve overwrites
        eq_dual, ineq_dual = form.duals(np.array(result.y, dtype=np.float64),
                                        np.array(result.z_u, dtype=np.float64))
        return DirectResult(
            x=np.array(form.mapping.primal(result.x, qp)), eq_dual=eq_dual,
            ineq_dual=ineq_dual,
            status=str(CvxpyPIQP.STATUS_MAP.get(result.info.status.name, cp.SOLVER_ERROR)),
            solver_time=min(native_time, float(result.info.run_time)),
            reported_time=float(result.info.run_time), native_time=native_time,
            iterations=int(result.info.iter))


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
        started = time.perf_counter()
        self.solver.update(q=q, b=b, A=a)
        result = self.solver.solve()
        native_time = time.perf_counter() - started
        z = np.asarray(result.z, dtype=np.float64)
        return DirectResult(
            x=m.primal(result.x, qp), eq_dual=m.eq_coefficient * z[m.eq_rows],
            ineq_dual=-m.ineq_coefficient * z[m.ineq_rows],
            status=str(CLARABEL.STATUS_MAP.get(str(result.status), cp.SOLVER_ERROR)),
            solver_time=min(native_time, float(result.solve_time)),
            reported_time=float(result.solve_time), native_time=native_time,
            iterations=int(result.iterations))


DirectSolver = DirectOSQP | DirectPIQP | DirectClarabel
"""A structure's direct path for one solver."""


def build_direct(solver: str, problem: cp.Problem, names: dict[int, str], qp: StepQP,
                 options: dict[str, Any]) -> DirectSolver | None:
    """Set up ``solver``'s direct path for a compiled ``problem`` whose parameters hold ``qp``.

    ``solver`` is one of :data:`DIRECT_SOLVERS` (OSQP, PIQP with its sparse backend,
    CLARABEL).  ``names`` maps our parameter ids to ``weighted_target``, ``eq_values``,
    ``eq_rhs``, ``ineq_values``, ``ineq_rhs``.  Returns ``None`` if cvxpy's internals are
    not as expected (the caller then keeps using ``Problem.solve()``).
    """
    try:
        return _BUILDERS[solver](problem, names, qp, options)
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

    built = _QPForm.of(problem, names, qp, cp.OSQP)
    if built is None:
        return None
    form, data = built
    stacked = _Gather.of(sp.vstack([form.eq.tags, form.ineq.tags]))
    reference = sp.csc_array(sp.vstack([data["A"], data["F"]]))
    reference.sort_indices()
    if not stacked.reproduces(reference, form.mapping.values(qp)[0]):
        return None
    settings = _osqp_settings(options)
    direct = DirectOSQP(form=form, stacked=stacked, solver=osqp.OSQP(), settings=settings)
    direct.solver.setup(P=sp.csc_matrix(sp.triu(data["P"], format="csc")), q=data["q"],
                        A=sp.csc_matrix(reference),
                        l=np.concatenate([data["b"], np.full(data["G"].shape[0], -np.inf)]),
                        u=np.concatenate([data["b"], data["G"]]), **settings)
    return direct


def _piqp_settings(options: dict[str, Any]) -> dict[str, Any]:
    settings = {key: value for key, value in options.items() if key not in _NOT_PIQP_SETTINGS}
    settings["verbose"] = False
    return settings


def _apply_piqp_settings(solver: Any, settings: dict[str, Any]) -> None:
    """Set PIQP's settings as cvxpy does (attribute by attribute)."""
    for name, value in settings.items():
        setattr(solver.settings, name, value)


def _build_piqp(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                options: dict[str, Any]) -> DirectPIQP | None:
    import piqp

    if options.get("backend", "sparse") != "sparse":
        return None
    built = _QPForm.of(problem, names, qp, cp.PIQP)
    if built is None:
        return None
    form, data = built
    settings = _piqp_settings(options)
    solver = piqp.SparseSolver()
    _apply_piqp_settings(solver, settings)
    values, _ = form.mapping.values(qp)  # A and F in the (sorted) patterns updates will use
    solver.setup(P=sp.csc_matrix(data["P"]), c=data["q"], A=form.eq.fill(values).copy(),
                 b=data["b"], G=form.ineq.fill(values).copy(), h_u=data["G"])
    return DirectPIQP(form=form, solver=solver, settings=settings)


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


_BUILDERS = {"OSQP": _build_osqp, "PIQP": _build_piqp, "CLARABEL": _build_clarabel}
DIRECT_SOLVERS = tuple(_BUILDERS)
"""Solvers with a direct path."""
