"""Warm starts across steps: contact ids, the mapped guess, and runs equal to cold ones."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kernel_paths import both
from qp_bank import AGREEMENT
from wuerfel_cvx import Scene, Simulation, simulate
from wuerfel_cvx.contacts import Contacts
from wuerfel_cvx.formulations import StepQP, get_formulation, step_qp
from wuerfel_cvx.model import Model, State
from wuerfel_cvx.solvers import available_solvers
from wuerfel_cvx.warm_start import WarmStarts, row_ids

pytestmark = pytest.mark.integration

WARM_SOLVERS = [name for name in ("OSQP", "PROXQP", "DAQP") if name in available_solvers()]


def _qp(scene: str, formulation: str = "rigid") -> StepQP:
    model = Model.from_scene(Scene.named(scene))
    state = State.initial(Scene.named(scene))
    return step_qp(get_formulation(formulation), model, state, 0.01)


def _reordered(qp: StepQP, order: np.ndarray) -> StepQP:
    """``qp`` with its contacts (and so its rows) in another order."""
    c = qp.contacts
    contacts = Contacts(*(getattr(c, name)[order] for name in
                          ("point", "edge_i", "edge_j", "point_body", "edge_body", "distance")))
    return StepQP(weights=qp.weights, target=qp.target, eq_matrix=qp.eq_matrix,
                  eq_rhs=qp.eq_rhs, ineq_matrix=qp.ineq_matrix[order], ineq_rhs=qp.ineq_rhs[order],
                  contacts=contacts)


def test_a_row_keeps_its_id_when_the_rows_are_reordered() -> None:
    qp = _qp("stack-3")
    order = np.arange(len(qp.contacts))[::-1].copy()
    ids, moved = row_ids(qp), row_ids(_reordered(qp, order))
    assert ids is not None and moved is not None
    assert np.unique(ids).size == ids.size  # one id per row
    assert np.array_equal(moved, ids[order])


def test_velocity_rows_have_one_id_per_block_and_contact() -> None:
    qp = _qp("stack-3", "velocity")
    ids = row_ids(qp)
    assert ids is not None and ids.size == qp.n_inequalities == 2 * len(qp.contacts)
    assert np.unique(ids).size == ids.size


def test_the_guess_carries_each_multiplier_to_the_row_of_the_same_contact() -> None:
    qp = _qp("stack-3")
    rows = qp.n_inequalities
    multipliers = np.arange(1.0, rows + 1)
    store = WarmStarts()
    store.remember("OSQP", qp, np.ones(qp.n_variables), np.zeros(0), multipliers, 1.0)
    order = np.arange(rows)[::-1].copy()
    guess = store.guess("OSQP", _reordered(qp, order), 1.0)
    assert guess is not None and guess.matched_rows == rows
    assert np.array_equal(guess.ineq_dual, multipliers[order])
    dropped = _reordered(qp, order[1:])  # a contact that is gone, none new
    partial = store.guess("OSQP", dropped, 1.0)
    assert partial is not None and np.array_equal(partial.ineq_dual, multipliers[order[1:]])
    assert store.guess("OSQP", qp, 2.0) is None  # other units: no guess
    assert store.guess("PIQP", qp, 1.0) is None  # another solver's solution is not taken


@pytest.mark.parametrize("solver", WARM_SOLVERS)
@pytest.mark.parametrize(("scene", "formulation"), [("pyramid-3", "rigid"),
                                                    ("corner-drop", "velocity")])
def test_a_warm_started_run_follows_the_cold_one_to_solver_tolerance(
        solver: str, scene: str, formulation: str) -> None:
    """Both runs solve the same QPs to ``eps``; their positions may part by about eps * t.

    Every step of both runs passes the KKT check (relative residuals below
    VERIFY_FACTOR * eps, eps = 1e-9 at ``high``): each step's velocities are then within
    about 100 eps m/s of the exact ones (the QP bank's agreement argument:
    tests/qp_bank.py), so over 60 steps of 0.01 s the two runs may part by
    60 * 0.01 s * 2 * 12 * 100 eps = 1.4e-6 m.  Measured: at most 5e-9 m (PROXQP on
    corner-drop); OSQP (polished) and DAQP (active set) give the same bits.
    """
    steps = 60
    runs = [simulate(scene, dt=0.01, steps=steps, solver=solver, formulation=formulation,
                     tol="high", warm_start=warm) for warm in (False, True)]
    cold, warm = runs
    assert cold.metrics["verified"].all() and warm.metrics["verified"].all()
    bound = steps * 0.01 * AGREEMENT  # m
    assert float(np.max(np.abs(warm.points - cold.points))) <= bound


@pytest.mark.parametrize("solver", [s for s in WARM_SOLVERS if s != "OSQP"])
def test_warm_starts_save_iterations_on_a_resting_stack(solver: str) -> None:
    """A resting stack's active set repeats: from last step's multipliers it is found at once."""
    totals = []
    for warm in (False, True):
        sim = Simulation(Scene.named("stack-3"), dt=0.01, solver=solver, formulation="rigid",
                         warm_start=warm)
        totals.append(sum(sim.step().solutions[0].iterations for _ in range(20)))
    assert totals[1] < totals[0]


@pytest.mark.parametrize("formulation", ["rigid", "velocity"])
def test_compiled_row_ids_are_the_numpy_ids(monkeypatch: pytest.MonkeyPatch,
                                            formulation: str) -> None:
    qp = _qp("stack-3", formulation)
    reference, compiled = both(monkeypatch, lambda: row_ids(qp))
    assert reference is not None and compiled is not None
    assert compiled.dtype == reference.dtype and np.array_equal(compiled, reference)
    big = dataclasses.replace(qp, contacts=dataclasses.replace(
        qp.contacts, point=qp.contacts.point + (1 << 16)))  # past the ids' 16 bits
    assert both(monkeypatch, lambda: row_ids(big)) == [None, None]
