"""Clarabel's direct backend: cvxpy's conic data updated in a persistent ``DefaultSolver``.

Clarabel takes cvxpy's conic data as ``A = -A_cone``, ``b = b_cone``; a multiplier ``z``
of a row with coefficient ``c`` is ``c z`` for an equality and ``-c z`` for an inequality
in our sign convention.  Clarabel's settings are fixed when a structure is set up.  Each
solve hands Clarabel ``A``'s nonzeros alone (its pattern is the structure's), which its
binding reads faster than a scipy matrix, with the same results.

:func:`solve_new` solves a structure seen for the first time from the step QP's own
numbers (:mod:`._native`, in ``d = x - t``) on a fresh solver, as ``[E; -G; G_u] d + s``
equal to its shifted ``[e; -h; u]``, with
``s`` in the zero cone, then the nonnegative cone; with ``P x + q + A' z = 0`` the
package's ``y`` is ``z`` on the first rows and its ``z`` is ``z_l - z_u``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..formulations.qp import StepQP
from ..geometry import FloatArray
from ..warm_start import WarmStart
from ._cvxpy import Unavailable, clarabel_settings, compile_conic, status_name
from ._map import DirectResult, ParameterMap, scaled
from ._native import NativeData, stacked


@dataclass
class DirectClarabel:
    """A structure's parameter map and its persistent Clarabel solver."""

    mapping: ParameterMap
    b_rows: np.ndarray
    solver: Any
    a_values: FloatArray
    """The nonzeros of ``A`` in the structure's pattern (CSC order), written in place."""

    def solve(self, qp: StepQP, settings: dict[str, Any],
              warm: WarmStart | None = None) -> DirectResult:
        """Solve ``qp`` (this structure); ``settings`` were fixed when it was set up."""
        m = self.mapping
        values, q = m.values(qp)
        np.negative(values[:m.n_matrix_entries], out=self.a_values)
        b = np.zeros(m.shape[0])
        b[self.b_rows] = values[m.n_matrix_entries:]
        started = time.perf_counter()
        self.solver.update(q=q, b=b, A=self.a_values)  # A's nonzeros, its pattern kept
        result = self.solver.solve()
        native_time = time.perf_counter() - started
        z = np.asarray(result.z, dtype=np.float64)
        eq_dual, ineq_dual = m.duals(qp, lambda block: scaled(z, block, 0, 1.0),
                                     lambda block: scaled(z, block, 0, -1.0))
        return DirectResult(
            x=m.primal(result.x, qp), eq_dual=eq_dual, ineq_dual=ineq_dual,
            status=status_name("CLARABEL", str(result.status)),
            reported_time=float(result.solve_time), native_time=native_time,
            iterations=int(result.iterations))


def _matrix(mapping: ParameterMap, values: np.ndarray) -> sp.csc_matrix:
    """Clarabel's ``A = -A_cone`` from the conic data's nonzeros."""
    count = mapping.n_matrix_entries
    return sp.csc_matrix((-values[:count], mapping.indices[:count], mapping.indptr[:-1]),
                         shape=(mapping.shape[0], mapping.shape[1] - 1))


def build(problem: Any, names: dict[int, str], qp: StepQP,
          options: dict[str, Any]) -> DirectClarabel:
    """Clarabel's direct path for a compiled ``problem`` whose parameters hold ``qp``."""
    import clarabel

    mapping, data = compile_conic(problem, names, qp)
    ours = sp.csc_array(_matrix(mapping, mapping.values(qp)[0]))
    reference = data.A
    if not (np.array_equal(reference.indptr, ours.indptr)
            and np.array_equal(reference.indices, ours.indices)
            and np.allclose(reference.data, ours.data, rtol=0, atol=1e-12)):
        raise Unavailable("the conic matrix does not reproduce cvxpy's")
    solver = clarabel.DefaultSolver(sp.csc_matrix(sp.triu(data.P).tocsc()), data.c,
                                    sp.csc_matrix(reference), data.b, data.cones,
                                    clarabel_settings(options))
    if not solver.is_data_update_allowed():
        raise Unavailable("Clarabel does not allow data updates with these settings")
    return DirectClarabel(mapping=mapping,
                          b_rows=np.asarray(mapping.indices[mapping.n_matrix_entries:]),
                          solver=solver, a_values=np.zeros(mapping.n_matrix_entries))


def solve_new(qp: StepQP, options: dict[str, Any]) -> DirectResult:
    """Solve ``qp`` on a fresh Clarabel solver from its own numbers (:mod:`._native`)."""
    import clarabel

    data = NativeData.of(qp)
    upper_rows = qp.upper_rows
    n_eq, n_ineq = qp.n_equalities, qp.n_inequalities
    rows = stacked((qp.eq_matrix, 1.0), (qp.ineq_matrix, -1.0),
                   (sp.csr_array(qp.ineq_matrix[upper_rows]), 1.0))
    cones = [clarabel.ZeroConeT(n_eq)] if n_eq else []
    if n_ineq + upper_rows.size:
        cones.append(clarabel.NonnegativeConeT(n_ineq + upper_rows.size))
    started = time.perf_counter()
    solver = clarabel.DefaultSolver(data.upper_triangle, data.linear, rows,
                                    np.concatenate([data.eq_rhs, -data.lower,
                                                    data.upper[upper_rows]]),
                                    cones, clarabel_settings(options))
    result = solver.solve()
    native_time = time.perf_counter() - started
    z = np.asarray(result.z, dtype=np.float64)
    ineq_dual = z[n_eq:n_eq + n_ineq].copy()
    ineq_dual[upper_rows] -= z[n_eq + n_ineq:]
    return DirectResult(
        x=data.unknowns(result.x), eq_dual=z[:n_eq].copy(), ineq_dual=ineq_dual,
        status=status_name("CLARABEL", str(result.status)),
        reported_time=float(result.solve_time), native_time=native_time,
        iterations=int(result.iterations))
