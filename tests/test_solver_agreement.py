"""Every registered solver agrees with CLARABEL on a bank of step QPs at tight tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from qp_bank import AGREEMENT, BANK_CASES, qp_bank
from wuerfel_cvx.solve import solve_step_qp
from wuerfel_cvx.solvers import available_solvers

pytestmark = pytest.mark.integration


def test_bank_covers_contacts_of_both_formulations() -> None:
    bank = qp_bank()
    assert len(bank) == len(BANK_CASES)
    with_contacts = [entry for entry in bank if entry.build().n_inequalities > 0]
    assert len(with_contacts) >= len(bank) - 2
    assert {entry.formulation for entry in with_contacts} == {"velocity", "seed"}


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
