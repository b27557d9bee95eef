"""Warm starts across steps: last step's solution mapped onto this step's rows.

A contact keeps its identity from step to step: its ids, the point and the edge's two
corners (:mod:`wuerfel_cvx.step.contacts`), name it, whatever its place among the rows.  A step
QP's inequality rows are its contacts' rows, one block of rows per contact after another
(the closest-approach rows of ``velocity``: all rate rows, then all approach rows), so each
row is named by ``(block, contact)``: row ``block * count + k`` of a QP with ``count``
contacts is its contact ``k``'s row of that block (:func:`row_blocks`).  The next QP's guess
(:meth:`WarmStarts.guess`) is then

* the unknowns: the last solution (the same bodies, so the same unknowns);
* the equality multipliers: the last ones when the equalities are the same rows (rods);
* each inequality multiplier: that of the row of the same block and contact in the last QP
  (the contact found among the last QP's by :class:`~wuerfel_cvx.step.contacts.ContactIndex`),
  0 for a contact that is new.

A warm start changes where a solver starts, never the problem: an iterative solver
(PROXQP) stops at the same tolerance, an active-set solver (DAQP) at the same optimum, and
every answer is checked by the same KKT residuals as a cold one.  QPs whose rows are not one
block per contact (friction cones) get the unknowns and rod multipliers only.  A QP with a
linear cost (the Coulomb fixed point's friction problem, :mod:`wuerfel_cvx.friction.problem`)
starts from the last such QP, and a step QP from the last step QP, so that the two problems
the fixed point alternates do not take each other's place.  Only the
solvers that take such a start (:attr:`~wuerfel_cvx.solve.registry.SolverSpec.takes_warm_start`)
have guesses made and solutions kept; OSQP starts from its structure's own last solution
(:mod:`wuerfel_cvx.solve.adapters.osqp`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..formulations.qp import StepQP
from ..scenes.geometry import FloatArray
from ..step.contacts import ContactIndex, carry_rows


def row_blocks(qp: StepQP) -> int | None:
    """How many blocks of one row per contact ``qp``'s inequality rows are; ``None`` if not.

    ``None`` when the rows are not one block per contact: friction cones, or a row count
    that is no multiple of the contacts (or rows without contacts).
    """
    contacts, rows = qp.contacts, qp.n_inequalities
    if rows == 0:
        return 0
    if qp.cones is not None or len(contacts) == 0 or rows % len(contacts):
        return None
    return rows // len(contacts)


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
    """The last solution of one solver, in the solver's units, with its rows' contacts."""

    x: FloatArray
    eq_dual: FloatArray
    ineq_dual: FloatArray
    contacts: ContactIndex | None
    """The QP's contacts, by their ids; ``None``: its rows are not blocks of contacts."""
    blocks: int
    """The QP's blocks of rows (:func:`row_blocks`)."""
    scale: float


@dataclass
class WarmStarts:
    """Each solver's last verified solution and how to map it onto the next QP."""

    _last: dict[tuple[str, bool], _Solved] = field(default_factory=dict, repr=False)
    """By solver and whether the QP has a linear cost."""
    guesses: int = 0
    """QPs given a warm start so far."""

    def remember(self, solver: str, qp: StepQP, x: FloatArray, eq_dual: FloatArray,
                 ineq_dual: FloatArray, scale: float) -> None:
        """Keep ``solver``'s solution of ``qp`` (solver units, unknowns scaled by ``scale``)."""
        blocks = row_blocks(qp)
        self._last[solver, qp.linear is not None] = _Solved(
            x=np.array(x, dtype=np.float64), eq_dual=np.array(eq_dual, dtype=np.float64),
            ineq_dual=np.array(ineq_dual, dtype=np.float64),
            contacts=None if blocks is None else ContactIndex.of(qp.contacts.ids()),
            blocks=blocks or 0, scale=scale)

    def guess(self, solver: str, qp: StepQP, scale: float) -> WarmStart | None:
        """The warm start for ``qp`` from ``solver``'s last solution; ``None`` if none fits.

        None fits when there is no last solution, it has other unknowns, or the solver sees
        the QP in other units (:mod:`wuerfel_cvx.solve.scaling`).
        """
        last = self._last.get((solver, qp.linear is not None))
        if last is None or last.x.shape[0] != qp.n_variables or last.scale != scale:
            return None
        eq_dual = (last.eq_dual if last.eq_dual.shape[0] == qp.n_equalities
                   else np.zeros(qp.n_equalities))
        ineq_dual = np.zeros(qp.n_inequalities)
        blocks = min(row_blocks(qp) or 0, last.blocks)  # the rows (block, contact) of both
        matched = 0
        if blocks and last.contacts is not None:
            matched = carry_rows(last.contacts.find(qp.contacts.ids()), last.ineq_dual,
                                 len(last.contacts), blocks, ineq_dual)
        self.guesses += 1
        return WarmStart(x=last.x, eq_dual=eq_dual, ineq_dual=ineq_dual, matched_rows=matched)

