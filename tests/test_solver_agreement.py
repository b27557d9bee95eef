"""Every registered solver agrees with CLARABEL on a bank of step QPs at tight tolerance."""

from __future__ import annotations

import numpy as np
import pytest

from qp_bank import BANK_CASES, qp_bank
from wuerfel_cvx.solve import VERIFY_FACTOR, solve_step_qp
from wuerfel_cvx.solvers import TOLERANCE_PRESETS, available_solvers

# Both solutions pass the residual check at VERIFY_FACTOR * eps (relative).  The QP is
# strongly convex with Hessian 2 W, W >= m/4 = 0.25 kg per coordinate for the bank's
# squares, and its right-hand sides and targets are below 5 m/s, so a residual r moves
# the minimiser by at most about r (1 + 5 m/s) / (2 * 0.25 kg) = 12 r; two solutions
# may differ by twice that.
AGREEMENT = 2 * 12 * VERIFY_FACTOR * TOLERANCE_PRESETS["high"]  # m/s (2.4e-6)


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
