"""The card house's Coulomb contact QP: why OSQP takes thousands of iterations on it.

Facts of one saved contact QP (``tests/fixtures/card-house/``, the first contact QP of
step 3 of ``wuerfel-cvx simulate card-house --dt 0.0166667 --friction-model coulomb``;
``reports/perf/coulomb-card-house.md``) that explain OSQP's cost and stay true whatever
the solvers' versions: the QP is well posed (CLARABEL verifies it at ``high``), its rows
active at the optimum are few and independent, but next to them lie rows that are
parallel to within 1e-6 and inactive by less than 0.1 mm/s (each resting contact's rate
row and closest-approach row). OSQP solves the QP restricted to its active rows at once
and the whole QP only after thousands of iterations; an adaptive step size that follows
the residuals within a factor of 2 (the package's option) takes fewer iterations than
OSQP's own factor of 5.  OSQP's staged solve (its answer checked at 200 iterations, then
at each doubling) leaves its iterates as they are.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from stalled_qps import load_step_qp
from wuerfel_cvx.formulations import StepQP
from wuerfel_cvx.solve import registry
from wuerfel_cvx.solve.adapters import Accept, Answer, NativeData
from wuerfel_cvx.solve.adapters import osqp as osqp_adapter
from wuerfel_cvx.solve.paths import SolvePath, StepSolution, solve_step_qp

pytestmark = pytest.mark.integration

FIXTURE = Path(__file__).resolve().parent / "fixtures" / "card-house" / \
    "card-house-coulomb-step3.npz"

ACTIVE_SLACK = 1e-7
"""Slack (m/s) below which a row counts as active: the ``default`` tolerance's eps, far above
the reference's verified residuals (as in ``tests/test_stalled_qps.py``)."""

NEAR_SLACK = 1e-4
"""Slack (m/s) below which an inactive row counts as nearly active."""

PARALLEL = 1e-6
"""``1 - cos`` below which two rows count as parallel."""


@pytest.fixture(scope="module")
def contact_qp() -> StepQP:
    """The saved contact QP."""
    qp, _ = load_step_qp(FIXTURE)
    return qp


@pytest.fixture(scope="module")
def reference(contact_qp: StepQP) -> StepSolution:
    """CLARABEL's solution at tol ``high``."""
    return solve_step_qp(contact_qp, "CLARABEL", "high")


def _slack(qp: StepQP, solution: StepSolution) -> np.ndarray:
    return np.asarray(qp.ineq_matrix @ solution.x - qp.ineq_rhs)


def _osqp(qp: StepQP, monkeypatch: pytest.MonkeyPatch | None = None, polishing: bool = False,
          **options: object) -> StepSolution:
    """``qp`` solved by OSQP at tol ``default`` on a fresh path, ``options`` overriding.

    Unpolished by default: OSQP runs to its own criteria (polished, it runs in stages).
    """
    if monkeypatch is not None:
        spec = registry.SOLVERS["OSQP"]
        monkeypatch.setitem(registry.SOLVERS, "OSQP", dataclasses.replace(
            spec, options=lambda eps: {**spec.options(eps), **options}))
    return solve_step_qp(qp, "OSQP", "default", path=SolvePath(), polishing=polishing)


def test_fixture_holds_the_card_house_contact_qp(contact_qp: StepQP) -> None:
    """40 cards: 8 corner velocities and 5 rods each, two rows per contact (rate, approach)."""
    assert contact_qp.n_variables == 8 * 40
    assert contact_qp.n_equalities == 5 * 40
    assert contact_qp.n_inequalities == 2 * len(contact_qp.contacts) > 0


def test_reference_solver_verifies_the_contact_qp(reference: StepSolution) -> None:
    """The QP is well posed: CLARABEL verifies an optimum at tol ``high``."""
    assert reference.status == "optimal"
    assert reference.verified, reference.residuals


def test_active_rows_are_few_and_independent(contact_qp: StepQP,
                                             reference: StepSolution) -> None:
    """Fewer active rows than rigid motions, and together with the rods of full rank."""
    active = _slack(contact_qp, reference) < ACTIVE_SLACK
    rigid_motions = contact_qp.n_variables - contact_qp.n_equalities
    assert 0 < np.count_nonzero(active) < rigid_motions
    rows = sp.vstack([contact_qp.eq_matrix, contact_qp.ineq_matrix[np.flatnonzero(active)]])
    assert np.linalg.matrix_rank(rows.toarray()) == rows.shape[0]


def test_resting_contacts_hold_parallel_rows_a_hair_apart(contact_qp: StepQP,
                                                          reference: StepSolution) -> None:
    """Contacts whose rate and closest-approach rows are parallel, one active, one not.

    A resting card barely turns in a step, so the gap's rate at the step's start and its
    mean rate up to the closest approach are the same row to ``1 - cos < 1e-6`` (55 of
    464 contacts here, down to 1e-13); where one is active the other is inactive by
    0.1 um/s to 0.1 mm/s.
    """
    count = len(contact_qp.contacts)
    rows = contact_qp.ineq_matrix.toarray()
    rate, approach = rows[:count], rows[count:]
    cosine = np.sum(rate * approach, axis=1) / (np.linalg.norm(rate, axis=1)
                                                * np.linalg.norm(approach, axis=1))
    slack = _slack(contact_qp, reference)
    rate_slack, approach_slack = slack[:count], slack[count:]
    one_active = np.minimum(rate_slack, approach_slack) < ACTIVE_SLACK
    other_near = (np.maximum(rate_slack, approach_slack) > ACTIVE_SLACK) \
        & (np.maximum(rate_slack, approach_slack) < NEAR_SLACK)
    pairs = (1.0 - cosine < PARALLEL) & one_active & other_near
    assert np.count_nonzero(pairs) >= 20


def test_osqp_solves_the_active_rows_at_once_and_the_whole_qp_slowly(
        contact_qp: StepQP, reference: StepSolution) -> None:
    """The same optimum: at most 500 iterations on its active rows, 5,000 or more on all.

    Polished, OSQP runs in stages and stops at the first whose answer polishes to the
    exact point: the first stage here, the same optimum.
    """
    active = np.flatnonzero(_slack(contact_qp, reference) < ACTIVE_SLACK)
    restricted = dataclasses.replace(contact_qp, ineq_matrix=contact_qp.ineq_matrix[active],
                                     ineq_rhs=contact_qp.ineq_rhs[active])
    few, whole = _osqp(restricted), _osqp(contact_qp)
    staged = _osqp(contact_qp, polishing=True)
    assert few.verified and whole.verified and staged.verified
    assert few.iterations <= 500
    assert whole.iterations >= 5_000
    assert staged.iterations == osqp_adapter.FIRST_STAGE
    for solution in (few, whole):
        np.testing.assert_allclose(solution.x, reference.x, atol=1e-6)
    np.testing.assert_allclose(staged.x, reference.x, atol=1e-9)


def test_adaptive_step_within_a_factor_two_saves_osqp_iterations(
        contact_qp: StepQP, monkeypatch: pytest.MonkeyPatch) -> None:
    """The package's ``adaptive_rho_tolerance`` of 2 beats OSQP's own 5 on this QP."""
    assert registry.solver_options("OSQP", "default")["adaptive_rho_tolerance"] == 2.0
    package = _osqp(contact_qp)
    own = _osqp(contact_qp, monkeypatch, adaptive_rho_tolerance=5.0)
    assert package.verified and own.verified
    assert package.iterations < own.iterations


def _staged(qp: StepQP, accept: Accept) -> Answer:
    """``qp`` solved by a fresh OSQP adapter in stages, ``accept`` checking each stage."""
    data = NativeData(qp)
    return osqp_adapter.setup(data, registry.solver_options("OSQP", "default")).solve(
        data, None, accept)


def test_osqp_stages_leave_its_iterates_unchanged(contact_qp: StepQP) -> None:
    """Stages of 200 then doubling, none accepted: bit for bit OSQP's own solve."""
    data = NativeData(contact_qp)
    plain = osqp_adapter.setup(data, registry.solver_options("OSQP", "default")).solve(data)
    checked: list[int] = []
    staged = _staged(contact_qp, lambda answer: checked.append(answer.iterations) or False)
    assert plain.status == staged.status == "optimal"
    assert staged.iterations == plain.iterations > osqp_adapter.FIRST_STAGE
    assert plain.x is not None and staged.x is not None
    np.testing.assert_array_equal(staged.x, plain.x)
    assert checked[:2] == [osqp_adapter.FIRST_STAGE] * 2  # then each stage the total so far
    assert all(later == 2 * earlier for earlier, later in zip(checked[1:], checked[2:],
                                                              strict=False))


def test_an_accepted_stage_ends_the_osqp_solve(contact_qp: StepQP) -> None:
    """The first stage's answer accepted: OSQP stops there, and says optimal."""
    staged = _staged(contact_qp, lambda answer: True)
    assert (staged.status, staged.iterations) == ("optimal", osqp_adapter.FIRST_STAGE)
