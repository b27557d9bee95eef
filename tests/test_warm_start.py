"""Warm starts across steps: rows found by block and contact, and runs equal to cold ones."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

from qp_bank import AGREEMENT
from wuerfel_cvx import Scene, Simulation, simulate
from wuerfel_cvx.formulations import StepQP, get_formulation, step_qp
from wuerfel_cvx.formulations.motion import corner_velocities
from wuerfel_cvx.solve.registry import available_solvers
from wuerfel_cvx.solve.warm_start import WarmStarts, row_blocks
from wuerfel_cvx.step.contacts import Contacts
from wuerfel_cvx.step.model import Model, State

pytestmark = pytest.mark.integration

WARM_SOLVERS = [name for name in ("OSQP", "PROXQP", "DAQP") if name in available_solvers()]


def _qp(scene: str, formulation: str = "rigid", spin: float = 0.0) -> StepQP:
    """The first step's QP; the boxes turning at ``spin``, ``-spin``, ... (rad/s) if given."""
    model = Model.from_scene(Scene.named(scene))
    state = State.initial(Scene.named(scene))
    if spin:
        turns = spin * (-1.0) ** np.arange(model.n_boxes)
        body = np.column_stack([np.zeros((model.n_boxes, 2)), turns])
        state = State(state.points, corner_velocities(state.points, body))
    return step_qp(get_formulation(formulation), model, state, 0.01)


def _reordered(qp: StepQP, order: np.ndarray) -> StepQP:
    """``qp`` with its contacts (and so its rows) in another order."""
    c = qp.contacts
    contacts = Contacts(*(getattr(c, name)[order] for name in
                          ("point", "edge_i", "edge_j", "point_body", "edge_body", "distance")))
    rows = _reordered_rows(qp, order)
    return StepQP(weights=qp.weights, target=qp.target, eq_matrix=qp.eq_matrix,
                  eq_rhs=qp.eq_rhs, ineq_matrix=qp.ineq_matrix[rows], ineq_rhs=qp.ineq_rhs[rows],
                  contacts=contacts)


def _reordered_rows(qp: StepQP, order: np.ndarray) -> np.ndarray:
    """The rows of ``qp`` in the order of :func:`_reordered` ``(qp, order)``'s rows."""
    blocks, count = row_blocks(qp), len(qp.contacts)
    assert blocks is not None
    return (np.arange(blocks)[:, None] * count + order).ravel()


# velocity: two blocks (rate rows, closest-approach rows) where the boxes move against
# each other, one where they rest on one another (each contact's two rows are one)
@pytest.mark.parametrize(("formulation", "spin", "blocks"),
                         [("rigid", 0.0, 1), ("velocity", 2.0, 2), ("velocity", 0.0, 1)])
def test_the_guess_carries_each_multiplier_to_the_row_of_the_same_block_and_contact(
        formulation: str, spin: float, blocks: int) -> None:
    qp = _qp("stack-3", formulation, spin)
    assert row_blocks(qp) == blocks and qp.n_inequalities == blocks * len(qp.contacts)
    multipliers = np.arange(1.0, qp.n_inequalities + 1)
    store = WarmStarts()
    store.remember("OSQP", qp, np.ones(qp.n_variables), np.zeros(0), multipliers, 1.0)
    order = np.arange(len(qp.contacts))[::-1].copy()
    guess = store.guess("OSQP", _reordered(qp, order), 1.0)
    assert guess is not None and guess.matched_rows == qp.n_inequalities
    assert np.array_equal(guess.ineq_dual, multipliers[_reordered_rows(qp, order)])
    dropped = _reordered(qp, order[1:])  # a contact that is gone, none new
    partial = store.guess("OSQP", dropped, 1.0)
    assert partial is not None
    assert np.array_equal(partial.ineq_dual, multipliers[_reordered_rows(qp, order[1:])])
    assert store.guess("OSQP", qp, 2.0) is None  # other units: no guess
    assert store.guess("PIQP", qp, 1.0) is None  # another solver's solution is not taken


def test_a_qp_with_a_linear_cost_does_not_take_the_step_qps_place() -> None:
    # the Coulomb fixed point alternates step QPs and friction problems (a linear cost)
    qp = _qp("stack-3")
    linear = dataclasses.replace(qp, linear=np.ones(qp.n_variables))
    store = WarmStarts()
    multipliers = np.arange(1.0, qp.n_inequalities + 1)
    store.remember("DAQP", qp, np.ones(qp.n_variables), np.zeros(0), multipliers, 1.0)
    assert store.guess("DAQP", linear, 1.0) is None  # no friction problem solved yet
    store.remember("DAQP", linear, np.full(qp.n_variables, 2.0), np.zeros(0),
                   -multipliers, 1.0)
    step_guess, linear_guess = store.guess("DAQP", qp, 1.0), store.guess("DAQP", linear, 1.0)
    assert step_guess is not None and linear_guess is not None
    assert np.array_equal(step_guess.x, np.ones(qp.n_variables))
    assert np.array_equal(step_guess.ineq_dual, multipliers)
    assert np.array_equal(linear_guess.x, np.full(qp.n_variables, 2.0))


def test_a_new_contact_and_a_new_block_start_from_zero() -> None:
    rigid = _qp("stack-3", "rigid")
    count = len(rigid.contacts)
    store = WarmStarts()
    store.remember("OSQP", rigid, np.ones(rigid.n_variables), np.zeros(0),
                   np.arange(1.0, count + 1), 1.0)
    two_blocks = dataclasses.replace(  # the same contacts, a second block of rows
        rigid, ineq_matrix=sp.vstack([rigid.ineq_matrix] * 2, format="csr"),
        ineq_rhs=np.r_[rigid.ineq_rhs, rigid.ineq_rhs])
    guess = store.guess("OSQP", two_blocks, 1.0)
    assert guess is not None and guess.matched_rows == count
    assert np.array_equal(guess.ineq_dual, np.r_[np.arange(1.0, count + 1), np.zeros(count)])
    moved = dataclasses.replace(rigid, contacts=dataclasses.replace(
        rigid.contacts, point=rigid.contacts.point + 4))  # every point another body's
    fresh = store.guess("OSQP", moved, 1.0)
    assert fresh is not None and fresh.matched_rows == 0 and not fresh.ineq_dual.any()


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
        # unpolished: polished, a resting stack's QPs are answered on the last active set
        # without any solver iteration
        sim = Simulation(Scene.named("stack-3"), dt=0.01, solver=solver, formulation="rigid",
                         warm_start=warm, polish=False)
        totals.append(sum(sim.step().solutions[0].iterations for _ in range(20)))
    assert totals[1] < totals[0]
