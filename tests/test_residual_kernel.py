"""The compiled KKT check (numba) gives the NumPy check's residuals bit for bit.

:func:`wuerfel_cvx.solve.kkt_residuals` runs its NumPy path with ``_numba.enabled`` false
(the reference) and :mod:`wuerfel_cvx.residual_kernel` with it true.  Both are run on the
step QPs of short runs (every formulation without a coupling cost or upper bounds), at the
solvers' answers, at perturbed points and multipliers, with NaN multipliers (as a solver
that returns no duals leaves them) and on QPs without equalities or without inequalities.
"""

from __future__ import annotations

import numpy as np
import pytest

from wuerfel_cvx import _numba, residual_kernel, simulate
from wuerfel_cvx.formulations.qp import StepQP
from wuerfel_cvx.solve import Residuals, StepSolution, kkt_residuals

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(not residual_kernel.AVAILABLE, reason="numba is not installed")]


def step_qps(scene: str, formulation: str, steps: int) -> list[tuple[StepQP, StepSolution]]:
    """The QPs and solutions of a short run."""
    seen: list[tuple[StepQP, StepSolution]] = []
    simulate(scene, dt=0.01, steps=steps, solver="OSQP", formulation=formulation,
             observer=lambda step, qp, solution: seen.append((qp, solution)))
    return seen


def both(monkeypatch: pytest.MonkeyPatch, qp: StepQP, x: np.ndarray, y: np.ndarray,
         z: np.ndarray) -> tuple[Residuals, Residuals]:
    results = []
    for enabled in (False, True):
        monkeypatch.setattr(_numba, "enabled", enabled)
        results.append(kkt_residuals(qp, x, y, z))
    return results[0], results[1]


def assert_same(reference: Residuals, compiled: Residuals) -> None:
    for name in ("primal", "dual", "complementarity"):
        ours, theirs = getattr(compiled, name), getattr(reference, name)
        assert (ours == theirs and np.signbit(ours) == np.signbit(theirs)) or (
            np.isnan(ours) and np.isnan(theirs)), name


@pytest.mark.parametrize(("scene", "formulation"), [
    ("stack-5", "velocity"), ("stack-5", "rigid"), ("rain-10", "velocity-baumgarte"),
    ("two-corner-landing", "seed"), ("pyramid-4", "rigid")])
def test_step_qps_give_the_same_residuals(monkeypatch: pytest.MonkeyPatch, scene: str,
                                          formulation: str) -> None:
    rng = np.random.default_rng(4)
    checked = 0
    for qp, solution in step_qps(scene, formulation, 30):
        if qp.cost_factor is not None or qp.ineq_upper is not None:
            continue
        y = rng.normal(size=qp.n_equalities)  # the solution does not carry y: any will do
        z = solution.ineq_dual
        for x, z_at in ((solution.x, z), (solution.x + rng.normal(scale=1e-3,
                                                                  size=solution.x.shape),
                                          z + rng.normal(size=z.shape))):
            assert_same(*both(monkeypatch, qp, x, y, z_at))
            checked += 1
        if z.size:
            assert_same(*both(monkeypatch, qp, solution.x, y, np.full(z.shape, np.nan)))
    assert checked > 0


def test_a_qp_without_rows_gives_the_same_residuals(monkeypatch: pytest.MonkeyPatch) -> None:
    qp, solution = step_qps("spinning-flight", "rigid", 1)[0]
    assert qp.n_equalities == qp.n_inequalities == 0
    assert_same(*both(monkeypatch, qp, solution.x, np.zeros(0), np.zeros(0)))
