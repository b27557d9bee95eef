"""The compiled KKT check (numba) gives the NumPy check's residuals bit for bit.

:func:`wuerfel_cvx.solve.kkt_residuals` runs its NumPy path with ``_numba.enabled`` false
(the reference) and :mod:`wuerfel_cvx.residual_kernel` with it true.  Both are run on the
step QPs of short runs (every formulation without a coupling cost or upper bounds), at the
solvers' answers, at perturbed points and multipliers, with NaN multipliers (as a solver
that returns no duals leaves them) and on QPs without equalities or without inequalities.
The compiled data check before a solve gives the NumPy path's scales and failures.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wuerfel_cvx import _numba, residual_kernel, simulate
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.formulations.qp import StepQP
from wuerfel_cvx.scaling import data_magnitude
from wuerfel_cvx.solve import Residuals, StepSolution, _checked_scales, kkt_residuals

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


def _scales(monkeypatch: pytest.MonkeyPatch, qp: StepQP, enabled: bool) -> tuple[float, float]:
    monkeypatch.setattr(_numba, "enabled", enabled)
    return _checked_scales(qp, 0, "OSQP")


@pytest.mark.parametrize(("scene", "formulation"), [("stack-5", "rigid"),
                                                    ("rain-10", "velocity-baumgarte")])
def test_the_data_check_gives_the_numpy_scales(monkeypatch: pytest.MonkeyPatch, scene: str,
                                               formulation: str) -> None:
    rng = np.random.default_rng(8)
    for qp, _ in step_qps(scene, formulation, 20):
        for target, weights in ((qp.target, qp.weights), (qp.target * 3e4, qp.weights * 1e-3)):
            varied = dataclasses.replace(qp, target=target, weights=weights)
            assert _scales(monkeypatch, varied, True) == _scales(monkeypatch, varied, False)
        finite, magnitude, largest = residual_kernel.data_summary(
            qp.weights, qp.target, qp.eq_matrix.data, qp.eq_rhs, qp.ineq_matrix.data,
            qp.ineq_rhs)
        assert finite and magnitude == data_magnitude(qp) and largest == qp.weights.max()
        field = str(rng.choice(["weights", "target", "eq_rhs", "ineq_rhs"]))
        values = np.array(getattr(qp, field), dtype=np.float64)
        if values.size:
            values[rng.integers(values.size)] = rng.choice([np.nan, np.inf, -np.inf])
            broken = dataclasses.replace(qp, **{field: values})
            for enabled in (True, False):
                monkeypatch.setattr(_numba, "enabled", enabled)
                with pytest.raises(StepFailure, match=f"non-finite {field}"):
                    _checked_scales(broken, 0, "OSQP")
