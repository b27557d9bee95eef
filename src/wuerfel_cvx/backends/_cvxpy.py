"""The adapter: every use of cvxpy's internals by the direct path is in this module.

The direct backends (:mod:`wuerfel_cvx.backends`) apply cvxpy's own parameter map by hand.
That map, the solvers' data as cvxpy formats them, cvxpy's status tables and its
translation of cones and settings for Clarabel are not public API.  They are read here,
and only for the cvxpy versions in :data:`TESTED_CVXPY`; the backends see plain numpy and
scipy data (:class:`~wuerfel_cvx.backends._map.ParameterMap`, :class:`QPData`,
:class:`ConicData`).

When the adapter cannot be used (another cvxpy version, internals not as expected, or a
map that does not reproduce cvxpy's own data) it raises :class:`Unavailable`;
:func:`wuerfel_cvx.backends.build_direct` turns that into one :class:`DirectPathWarning`
per solver and reason, and the step is solved through ``Problem.solve()`` instead.
"""

from __future__ import annotations

import importlib
import warnings
from dataclasses import dataclass
from functools import cache
from importlib.metadata import PackageNotFoundError, version
from typing import Any

import cvxpy as cp
import numpy as np
import scipy.sparse as sp

from ..formulations.qp import PARAMETER_SLOTS, StepQP
from ..geometry import FloatArray
from ._map import ParameterMap

TESTED_CVXPY: tuple[tuple[int, int], tuple[int, int]] = ((1, 9), (1, 9))
"""Oldest and newest (major, minor) cvxpy release whose internals this adapter was checked
against (the tests of :mod:`wuerfel_cvx.backends` compare its maps with cvxpy's data)."""

INTERNALS_CHANGED: tuple[type[Exception], ...] = (AttributeError, KeyError, TypeError,
                                                  IndexError, ImportError)
"""What reading cvxpy internals raises when they are not as this adapter expects."""

_STATUS_MAPS = {
    "OSQP": ("cvxpy.reductions.solvers.qp_solvers.osqp_qpif", "OSQP"),
    "PIQP": ("cvxpy.reductions.solvers.qp_solvers.piqp_qpif", "PIQP"),
    "CLARABEL": ("cvxpy.reductions.solvers.conic_solvers.clarabel_conif", "CLARABEL"),
    "PROXQP": ("cvxpy.reductions.solvers.qp_solvers.proxqp_qpif", "PROXQP"),
    "DAQP": ("cvxpy.reductions.solvers.qp_solvers.daqp_qpif", "DAQP"),
}


class DirectPathWarning(UserWarning):
    """The direct path cannot be used for a solver; steps go through ``Problem.solve()``."""


class Unavailable(Exception):
    """The direct path does not apply to a structure (the message says why)."""


_warned: set[tuple[str, str]] = set()


def warn_unavailable(solver: str, reason: str) -> None:
    """Warn (once per ``solver`` and ``reason``) that ``solver``'s direct path is not used."""
    if (solver, reason) in _warned:
        return
    _warned.add((solver, reason))
    warnings.warn(f"{solver}: direct path not used ({reason}); solving through cvxpy",
                  DirectPathWarning, stacklevel=3)


def check_version() -> None:
    """Raise :class:`Unavailable` unless the installed cvxpy is in :data:`TESTED_CVXPY`."""
    try:
        installed = version("cvxpy")
    except PackageNotFoundError:
        installed = cp.__version__
    parts = installed.split(".")
    try:
        release = (int(parts[0]), int(parts[1]))
    except (IndexError, ValueError):
        raise Unavailable(f"cannot read the cvxpy version '{installed}'") from None
    oldest, newest = TESTED_CVXPY
    if not oldest <= release <= newest:
        raise Unavailable(f"cvxpy {installed} is outside the tested "
                          f"{oldest[0]}.{oldest[1]} to {newest[0]}.{newest[1]}")


@cache
def _status_map(solver: str) -> dict[object, str]:
    """The map cvxpy has from ``solver``'s native statuses to its status names."""
    module, name = _STATUS_MAPS[solver]
    table: dict[object, str] = getattr(importlib.import_module(module), name).STATUS_MAP
    return table


def status_name(solver: str, native_status: object) -> str:
    """The status name cvxpy gives a native ``solver`` status (``solver_error`` if unknown)."""
    table = _status_map(solver)
    return str(table.get(native_status, cp.SOLVER_ERROR))


@dataclass(frozen=True)
class QPData:
    """cvxpy's QP form ``min 1/2 x' P x + q' x``, ``A x = b``, ``F x <= g`` (OSQP, PIQP)."""

    P: sp.csc_matrix
    q: FloatArray
    A: sp.csc_array
    b: FloatArray
    F: sp.csc_array
    g: FloatArray
    n_eq: int


@dataclass(frozen=True)
class ConicData:
    """cvxpy's conic form for Clarabel: ``min 1/2 x' P x + c' x``, ``b - A x`` in ``cones``."""

    P: sp.csc_matrix
    c: FloatArray
    A: sp.csc_array
    b: FloatArray
    cones: list[Any]


def compile_qp(problem: cp.Problem, names: dict[int, str], qp: StepQP,
               solver: str) -> tuple[ParameterMap, QPData]:
    """The parameter map and QP form cvxpy makes of ``problem`` for ``solver`` (OSQP or PIQP)."""
    mapping, data = _parameter_map(problem, names, qp, solver)
    return mapping, QPData(P=sp.csc_matrix(data["P"]), q=np.asarray(data["q"]),
                           A=_sorted_csc(data["A"]), b=np.asarray(data["b"]),
                           F=_sorted_csc(data["F"]), g=np.asarray(data["G"]),
                           n_eq=int(data["n_eq"]))


def compile_conic(problem: cp.Problem, names: dict[int, str],
                  qp: StepQP) -> tuple[ParameterMap, ConicData]:
    """The parameter map and conic data cvxpy makes of ``problem`` for Clarabel."""
    from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import dims_to_solver_cones

    mapping, data = _parameter_map(problem, names, qp, cp.CLARABEL)
    return mapping, ConicData(P=sp.csc_matrix(data["P"]), c=np.asarray(data["c"]),
                              A=_sorted_csc(data["A"]), b=np.asarray(data["b"]),
                              cones=dims_to_solver_cones(data["dims"]))


def clarabel_settings(options: dict[str, Any]) -> Any:
    """Clarabel's settings object for ``options``, built as cvxpy builds it."""
    from cvxpy.reductions.solvers.conic_solvers.clarabel_conif import CLARABEL

    return CLARABEL().parse_solver_opts(False, dict(options))


def _sorted_csc(matrix: Any) -> sp.csc_array:
    result = sp.csc_array(matrix)
    result.sort_indices()
    return result


def _parameter_map(problem: cp.Problem, names: dict[int, str], qp: StepQP,
                   solver: str) -> tuple[ParameterMap, dict[str, Any]]:
    """Compile ``problem`` for ``solver`` and read cvxpy's parameter map off its program."""
    check_version()
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
            raise Unavailable("a parameter of the compiled problem is no step-QP slot")
        slots.append((int(column), int(program.param_id_to_size[param_id]), names[ours]))
    tensor = program.reduced_A
    tensor.cache(keep_zeros=True)
    indices, indptr, shape = tensor.problem_data_index
    reduced_map = sp.csr_array(tensor.reduced_mat)
    offset_entries = (int(indptr[-2]), int(indptr[-1]))
    rhs_rows = {}
    for name in qp.slots():
        block = PARAMETER_SLOTS[name].multiplier
        if block is not None:
            rhs_rows[block] = _rhs_rows(reduced_map, np.asarray(indices), offset_entries,
                                        slots, name, PARAMETER_SLOTS[name].values(qp).size)
    empty = (np.zeros(0, np.int64), np.zeros(0))
    mapping = ParameterMap(
        slots=tuple(slots), vector_size=int(program.total_param_size) + 1,
        reduced_map=reduced_map, q_map=sp.csr_array(program.q), indices=np.asarray(indices),
        indptr=np.asarray(indptr), shape=(int(shape[0]), int(shape[1])),
        x_offset=int(program.var_id_to_col[problem.variables()[0].id]),
        eq=rhs_rows.get("eq", empty), lower=rhs_rows.get("lower", empty),
        upper=rhs_rows.get("upper"))
    return mapping, data


def _rhs_rows(reduced_map: sp.csr_array, indices: np.ndarray, offset_entries: tuple[int, int],
              slots: list[tuple[int, int, str]], source: str,
              count: int) -> tuple[np.ndarray, FloatArray]:
    """Conic row and coefficient of each right-hand side in slot ``source`` (``count``).

    Each must enter the conic data exactly once, in the offset column.
    """
    start = next((s for s, size, name in slots if name == source and size == count), None)
    if start is None:
        raise Unavailable(f"no parameter of size {count} holds '{source}'")
    columns = sp.csc_array(reduced_map[:, start:start + count])
    first, last = offset_entries
    rows, coefficients = np.zeros(count, np.int64), np.zeros(count)
    for j in range(count):
        entries = columns.indices[columns.indptr[j]:columns.indptr[j + 1]]
        if entries.size != 1 or not first <= entries[0] < last:
            raise Unavailable(f"'{source}' does not enter the conic data once, as an offset")
        rows[j] = indices[entries[0]]
        coefficients[j] = columns.data[columns.indptr[j]]
    return rows, coefficients
