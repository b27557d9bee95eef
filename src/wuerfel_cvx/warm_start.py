"""Warm starts across steps: last step's solution mapped onto this step's rows.

A contact keeps its identity from step to step: the point and the edge (its two corner
indices in the all-points array) name it, whatever its place among the rows.  A step QP's
inequality rows are its contacts' rows, one block of rows per contact after another (the
closest-approach rows of ``velocity``: all rate rows, then all approach rows), so each row
has a *row id* ``(block, point, edge_i, edge_j)`` (:func:`row_ids`).  The next QP's guess
(:meth:`WarmStarts.guess`) is then

* the unknowns: the last solution (the same bodies, so the same unknowns);
* the equality multipliers: the last ones when the equalities are the same rows (rods);
* each inequality multiplier: that of the row with the same id in the last QP, 0 for a
  contact that is new.

A warm start changes where a solver starts, never the problem: an iterative solver
(PROXQP) stops at the same tolerance, an active-set solver (DAQP) at the same optimum, and
every answer is checked by the same KKT residuals as a cold one.  QPs whose rows are not one
block per contact (friction cones) get the unknowns and rod multipliers only.  Only the
solvers that take such a start (:attr:`~wuerfel_cvx.solvers.SolverSpec.takes_warm_start`)
have guesses made and solutions kept; OSQP starts from its structure's own last solution
(:mod:`wuerfel_cvx.backends.osqp`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import _numba, map_kernel
from .formulations.qp import StepQP
from .geometry import FloatArray
from .model import IntArray

_INDEX_BITS = 16
"""Bits per point index in a row id: all-points indices below 2**16 (16 384 boxes)."""


def row_ids(qp: StepQP) -> IntArray | None:
    """One int64 id per inequality row of ``qp``, from its contact and block; ``None``.

    ``None`` when the rows are not one block per contact (friction cones, or a row count
    that is no multiple of the contacts) or an index does not fit :data:`_INDEX_BITS`.
    """
    contacts, rows = qp.contacts, qp.n_inequalities
    count = len(contacts)
    if rows == 0:
        return np.zeros(0, dtype=np.int64)
    if qp.cones is not None or count == 0 or rows % count:
        return None
    if _numba.enabled:  # the same ids, by a compiled loop
        ids = map_kernel.row_ids(contacts.point.astype(np.int64, copy=False),
                                 contacts.edge_i.astype(np.int64, copy=False),
                                 contacts.edge_j.astype(np.int64, copy=False),
                                 rows // count, _INDEX_BITS)
        return ids if ids.size else None
    limit = 1 << _INDEX_BITS
    if max(int(contacts.point.max()), int(contacts.edge_i.max()),
           int(contacts.edge_j.max())) >= limit:
        return None
    one = ((contacts.point.astype(np.int64) << (2 * _INDEX_BITS))
           | (contacts.edge_i.astype(np.int64) << _INDEX_BITS)
           | contacts.edge_j.astype(np.int64))
    return np.concatenate([one + (block << (3 * _INDEX_BITS)) for block in range(rows // count)])


@dataclass(frozen=True)
class WarmStart:
    """A guess for one QP, in the units the solver sees (those of the scaled QP)."""

    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    """``z = z_lower - z_upper`` per inequality row (0 for a row without a match)."""
    matched_rows: int
    """Inequality rows whose multiplier came from a row with the same id."""


@dataclass(frozen=True)
class _Solved:
    """The last solution of one solver, in the solver's units, with its rows' ids."""

    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    ids: IntArray | None
    scale: float


@dataclass
class WarmStarts:
    """Each solver's last verified solution and how to map it onto the next QP."""

    _last: dict[str, _Solved] = field(default_factory=dict, repr=False)
    _ids_of: tuple[StepQP, IntArray | None] | None = field(default=None, repr=False)
    """The last QP given a guess and its row ids, for :meth:`remember` of the same QP."""
    guesses: int = 0
    """QPs given a warm start so far."""

    def remember(self, solver: str, qp: StepQP, x: FloatArray, eq_dual: FloatArray,
                 ineq_dual: FloatArray, scale: float) -> None:
        """Keep ``solver``'s solution of ``qp`` (solver units, unknowns scaled by ``scale``)."""
        ids = self._row_ids(qp)
        order = None if ids is None else np.argsort(ids, kind="stable")
        self._last[solver] = _Solved(
            x=np.array(x, dtype=np.float64), eq_dual=np.array(eq_dual, dtype=np.float64),
            ineq_dual=np.array(ineq_dual if order is None else ineq_dual[order],
                               dtype=np.float64),
            ids=None if ids is None or order is None else ids[order], scale=scale)

    def guess(self, solver: str, qp: StepQP, scale: float) -> WarmStart | None:
        """The warm start for ``qp`` from ``solver``'s last solution; ``None`` if none fits.

        None fits when there is no last solution, it has other unknowns, or the solver sees
        the QP in other units (:mod:`wuerfel_cvx.scaling`).
        """
        last = self._last.get(solver)
        if last is None or last.x.shape[0] != qp.n_variables or last.scale != scale:
            return None
        eq_dual = (last.eq_dual if last.eq_dual.shape[0] == qp.n_equalities
                   else np.zeros(qp.n_equalities))
        ineq_dual = np.zeros(qp.n_inequalities)
        matched = 0
        ids = self._row_ids(qp)
        if ids is not None and last.ids is not None and last.ids.size and ids.size:
            place = np.minimum(np.searchsorted(last.ids, ids), last.ids.size - 1)
            hit = last.ids[place] == ids
            ineq_dual[hit] = last.ineq_dual[place[hit]]
            matched = int(np.count_nonzero(hit))
        self.guesses += 1
        return WarmStart(x=last.x, eq_dual=eq_dual, ineq_dual=ineq_dual, matched_rows=matched)

    def _row_ids(self, qp: StepQP) -> IntArray | None:
        """:func:`row_ids` of ``qp``, computed once for its guess and its solution."""
        if self._ids_of is None or self._ids_of[0] is not qp:
            self._ids_of = (qp, row_ids(qp))
        return self._ids_of[1]
