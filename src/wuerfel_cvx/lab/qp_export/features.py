"""What makes an exported step QP hard: its active set, conditioning, masses and overlap.

Measured at the reference solution (the run's own verified solution of the QP, CLARABEL at
``high``), in the qpsolvers form of :mod:`.problem`:

- *active rows*: rows of ``G x <= h`` whose slack ``h - G x`` is within
  :data:`ACTIVE_TOLERANCE` of zero, relative to ``1 + max(|h|, |G x|)`` (the primal scale
  of :func:`wuerfel_cvx.solve.paths.kkt_residuals`);
- *active rank*: the rank of ``[A; G_active]``.  Fewer than its rows: the active
  constraints are linearly dependent (a resting stack's coincident rows, a redundant rod),
  so their multipliers are not unique and the KKT matrix below is singular;
- *condition estimate*: the 2-norm condition number of the KKT matrix at the active set,
  ``[[P, G_act', A'], [G_act, 0, 0], [A, 0, 0]]`` (the matrix of ``qpsolvers.Problem.cond``);
- *mass ratio*: the largest over the smallest objective weight (kg) of the unknowns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...formulations.qp import StepQP
from ...scenes.geometry import FloatArray
from .problem import QPData

ACTIVE_TOLERANCE = 1e-6
"""Relative slack (1) under which a row counts as active: ten times the largest residual a
step verified at ``high`` may have (``VERIFY_FACTOR * 1e-9 = 1e-7``), so a row the
reference solution leaves this close to its bound cannot be told from an active one."""

DEEP_OVERLAP = 1e-4
"""Penetration (m) from which a QP's state counts as deeply overlapped: a hundred times the
contact search's ``gap_tolerance`` (1e-6 m)."""

MASS_RATIO = 100.0
"""Weight ratio (1) from which a QP counts as having a large mass ratio."""


@dataclass(frozen=True)
class Features:
    """Size and difficulty of one exported QP."""

    n_variables: int
    n_equalities: int
    n_inequalities: int
    n_active: int
    """Active rows of ``G`` at the reference solution."""
    active_rank: int
    """Rank of ``[A; G_active]``."""
    condition: float
    """2-norm condition number of the KKT matrix at the active set (``inf``: singular)."""
    mass_ratio: float
    """Largest over smallest objective weight of the unknowns (1)."""
    penetration_m: float
    """Deepest penetration (m) among the QP's contacts."""
    friction: bool
    """The QP holds friction cones (the ``ccp`` rows)."""

    @property
    def degenerate(self) -> bool:
        """The active constraints and equalities are linearly dependent."""
        return self.active_rank < self.n_active + self.n_equalities

    def tags(self, table_mass: float | None = None) -> list[str]:
        """Short words naming what makes the QP hard (``contact`` if nothing else)."""
        tags = []
        if table_mass is not None:
            tags.append(f"table{_short(table_mass)}kg")
        elif self.mass_ratio >= MASS_RATIO:
            tags.append(f"ratio{_short(self.mass_ratio)}")
        if self.degenerate:
            tags.append("degenerate")
        if self.penetration_m >= DEEP_OVERLAP:
            tags.append("overlap")
        if self.friction:
            tags.append("cone")
        return tags or ["contact"]


def _short(value: float) -> str:
    """``1e+06`` as ``1e6``: a power of ten for a file name."""
    mantissa, exponent = f"{value:.0e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def active_rows(data: QPData, x: FloatArray) -> np.ndarray:
    """Indices of the rows of ``G x <= h`` active at ``x`` (:data:`ACTIVE_TOLERANCE`)."""
    if data.G is None or data.h is None:
        return np.zeros(0, dtype=np.int64)
    lhs = data.G @ x
    scale = 1.0 + max(float(np.max(np.abs(data.h))), float(np.max(np.abs(lhs))))
    return np.flatnonzero(data.h - lhs <= ACTIVE_TOLERANCE * scale).astype(np.int64)


def kkt_matrix(data: QPData, active: np.ndarray) -> FloatArray:
    """``[[P, G_act', A'], [G_act, 0, 0], [A, 0, 0]]`` for the ``active`` rows of ``G``."""
    blocks = [] if data.G is None else [data.G[active]]
    if data.A is not None:
        blocks.append(data.A)
    if not blocks:
        return data.P
    constraints = np.vstack(blocks)
    m = constraints.shape[0]
    return np.block([[data.P, constraints.T], [constraints, np.zeros((m, m))]])


def features(qp: StepQP, data: QPData, x: FloatArray) -> Features:
    """The :class:`Features` of ``qp`` (in qpsolvers' form ``data``) at its solution ``x``."""
    active = active_rows(data, x)
    rows = [] if data.G is None else [data.G[active]]
    if data.A is not None:
        rows.append(data.A)
    stacked = np.vstack(rows) if rows else np.zeros((0, data.n_variables))
    rank = int(np.linalg.matrix_rank(stacked)) if stacked.shape[0] else 0
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        condition = float(np.linalg.cond(kkt_matrix(data, active)))
    weights = qp.weights
    return Features(
        n_variables=data.n_variables, n_equalities=data.n_equalities,
        n_inequalities=data.n_inequalities, n_active=int(active.size), active_rank=rank,
        condition=condition if np.isfinite(condition) else float("inf"),
        mass_ratio=float(np.max(weights) / np.min(weights)),
        penetration_m=qp.contacts.deepest_penetration(), friction=qp.cones is not None)
