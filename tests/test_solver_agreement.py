"""Every registered solver agrees with CLARABEL on a bank of step QPs at tight tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from qp_bank import AGREEMENT, BANK_CASES, qp_bank
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.solve.paths import solve_step_qp
from wuerfel_cvx.solve.registry import available_solvers

pytestmark = pytest.mark.integration


def test_bank_covers_contacts_of_both_formulations() -> None:
    bank = qp_bank()
    assert len(bank) == len(BANK_CASES)
    with_contacts = [entry for entry in bank if entry.build().n_inequalities > 0]
    assert len(with_contacts) >= len(bank) - 2
    assert {entry.formulation for entry in with_contacts} == {"velocity", "seed"}


#: Solvers whose claims of optimality on the bank are known to fail the KKT check unpolished,
#: and why.  Polished on their active sets, their answers pass it (the first test).  HiGHS
#: was here until it was handed the step QP's own form without its Hessian regularisation
#: (``docs/solver-failures.md``): its duals missed stationarity by up to 4e-6.
FAILS_THE_CHECK: dict[str, str] = {}


@pytest.mark.parametrize("solver", available_solvers())
def test_solver_agrees_with_clarabel_on_new_velocities(solver: str) -> None:
    for entry in qp_bank():
        reference = solve_step_qp(entry.build(), "CLARABEL", "high")
        candidate = solve_step_qp(entry.build(), solver, "high")
        assert reference.verified, entry.label
        assert candidate.verified, (entry.label, candidate.residuals)
        disagreement = float(np.max(np.abs(candidate.x - reference.x)))
        assert disagreement <= AGREEMENT, (entry.label, disagreement)


def test_the_core_solvers_are_installed() -> None:
    assert {"CLARABEL", "OSQP", "PIQP"} <= set(available_solvers())


@pytest.mark.parametrize("solver", sorted(set(FAILS_THE_CHECK) & set(available_solvers())))
def test_a_solver_failing_the_check_is_caught_and_its_primal_still_agrees(solver: str) -> None:
    """The KKT check, not the solver's word, decides; where the check passes, x agrees."""
    caught = 0
    for entry in qp_bank():
        reference = solve_step_qp(entry.build(), "CLARABEL", "high")
        try:
            candidate = solve_step_qp(entry.build(), solver, "high", polishing=False)
        except StepFailure as failure:
            assert failure.status != "optimal", entry.label
            caught += 1
            continue
        if not candidate.verified:  # AGREEMENT follows from the residuals: none here
            caught += 1
            continue
        disagreement = float(np.max(np.abs(candidate.x - reference.x)))
        assert disagreement <= AGREEMENT, (entry.label, disagreement)
    assert caught > 0  # the reason recorded in FAILS_THE_CHECK still holds
