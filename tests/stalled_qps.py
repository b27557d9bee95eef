"""Step QPs on which solvers stalled, saved as ``.npz`` fixtures, and their loader.

Each fixture in ``tests/fixtures/stalled/`` holds one step QP of the velocity formulation
(dt 0.01 s, tol ``default``), rebuilt from the state before the step a solver failed on
(``tests/fixtures/stalled/make_fixtures.py`` writes them; its README says how).  The saved
QPs keep the contact rows of the search at the time (each corner held by the edge of its
largest signed distance); :func:`rebuilt_step_qp` builds the same state's QP with the
current search.  Sparse
matrices are stored as CSR ``data``/``indices``/``indptr``/``shape``; the contacts' index
arrays and distances, and the state (corner positions and velocities), are kept beside
them so that the rows can be traced back to bodies.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from wuerfel_cvx import Scene
from wuerfel_cvx.formulations import StepQP, declare_qp, get_formulation, step_qp
from wuerfel_cvx.step.contacts import Contacts
from wuerfel_cvx.step.model import Model, State

STALLED_DIR = Path(__file__).resolve().parent / "fixtures" / "stalled"

DT = 0.01
"""Time step (s) of every stalled run."""


@dataclass(frozen=True)
class StalledCase:
    """A run that stopped: scene, solver, the failed step and the status it failed with."""

    scene: str
    solver: str
    step: int
    status: str
    reference: str
    """A solver that solves this QP at tol ``high`` with verified residuals."""

    @property
    def path(self) -> Path:
        """The fixture file of this case."""
        return STALLED_DIR / f"{self.scene}-{self.solver.lower()}-step{self.step}.npz"


STALLED_CASES: tuple[StalledCase, ...] = (
    StalledCase("rain-20", "OSQP", 103, "user_limit", "CLARABEL"),
    StalledCase("rain-20", "PIQP", 197, "user_limit", "CLARABEL"),
    StalledCase("rain-20", "CLARABEL", 353, "solver_error", "PIQP"),
    StalledCase("rain-50", "CLARABEL", 737, "solver_error", "PIQP"),
)
"""The stalls of the velocity formulation at dt 0.01 s and tol ``default``."""

_CONTACT_FIELDS = ("point", "edge_i", "edge_j", "point_body", "edge_body", "distance")


def _csr_arrays(prefix: str, matrix: sp.csr_array) -> dict[str, np.ndarray]:
    return {f"{prefix}_data": matrix.data, f"{prefix}_indices": matrix.indices,
            f"{prefix}_indptr": matrix.indptr, f"{prefix}_shape": np.asarray(matrix.shape)}


def _csr(arrays: Any, prefix: str) -> sp.csr_array:
    shape = tuple(int(n) for n in arrays[f"{prefix}_shape"])
    return sp.csr_array((arrays[f"{prefix}_data"], arrays[f"{prefix}_indices"],
                         arrays[f"{prefix}_indptr"]), shape=shape)


def save_step_qp(path: Path, qp: StepQP, state: State) -> None:
    """Write ``qp``'s numeric data, its contacts and the ``state`` it was built from."""
    if qp.ineq_upper is not None or qp.cost_factor is not None:
        raise ValueError("only one-sided QPs without a coupling cost are saved")
    arrays: dict[str, np.ndarray] = {
        "weights": qp.weights, "target": qp.target, "eq_rhs": qp.eq_rhs,
        "ineq_rhs": qp.ineq_rhs, "points": state.points, "velocities": state.velocities,
        **_csr_arrays("eq", qp.eq_matrix), **_csr_arrays("ineq", qp.ineq_matrix)}
    for name in _CONTACT_FIELDS:
        arrays[f"contact_{name}"] = getattr(qp.contacts, name)
    np.savez_compressed(path, **arrays)


def load_step_qp(path: Path) -> tuple[StepQP, State]:
    """The QP and the state of a fixture written by :func:`save_step_qp`."""
    with np.load(path) as arrays:
        contacts = Contacts(*(arrays[f"contact_{name}"] for name in _CONTACT_FIELDS))
        qp = declare_qp(arrays["weights"], arrays["target"], _csr(arrays, "eq"),
                        arrays["eq_rhs"], _csr(arrays, "ineq"), arrays["ineq_rhs"], contacts)
        return qp, State(arrays["points"], arrays["velocities"])


def rebuilt_step_qp(case: StalledCase) -> tuple[StepQP, State]:
    """The QP of the fixture's state as the velocity formulation builds it now."""
    _, state = load_step_qp(case.path)
    model = Model.from_scene(Scene.named(case.scene))
    return step_qp(get_formulation("velocity"), model, state, DT), state


def rigid_basis(state: State) -> np.ndarray:
    """``T`` (8 n, 3 n): corner velocities of each square's rigid motion (vx, vy, omega)."""
    corners = state.points.reshape(-1, 4, 2)
    n = corners.shape[0]
    basis = np.zeros((8 * n, 3 * n))
    for k in range(n):
        arm = corners[k] - corners[k].mean(axis=0)
        for c in range(4):
            row = 8 * k + 2 * c
            basis[row, 3 * k], basis[row + 1, 3 * k + 1] = 1.0, 1.0
            basis[row, 3 * k + 2], basis[row + 1, 3 * k + 2] = -arm[c, 1], arm[c, 0]
    return basis


def opposed_pairs(qp: StepQP, state: State, closeness: float = 1e-4) -> np.ndarray:
    """(pairs, 2) contact rows whose rigid rows ``g T`` point in opposite directions.

    Rows ``i < j`` with ``1 + cos(g_i T, g_j T) < closeness``: two point-edge rows that
    push the same relative motion of two bodies in opposite senses.
    """
    rigid = qp.ineq_matrix.toarray() @ rigid_basis(state)
    unit = rigid / np.linalg.norm(rigid, axis=1)[:, None]
    return np.argwhere(np.triu(unit @ unit.T < -1.0 + closeness, 1))
