"""The direct path (OSQP, PIQP, Clarabel): cvxpy's parameter map, a persistent solver."""

from __future__ import annotations

import dataclasses
import time
import warnings
from typing import Any

import numpy as np
import pytest

from qp_bank import AGREEMENT, qp_bank
from wuerfel_cvx import simulate
from wuerfel_cvx.backends import DirectPathWarning, DirectSolver, _cvxpy, build_direct
from wuerfel_cvx.backends.clarabel import DirectClarabel
from wuerfel_cvx.backends.osqp import DirectOSQP
from wuerfel_cvx.backends.piqp import DirectPIQP
from wuerfel_cvx.compiled import CompiledQP, CompiledQPCache
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.formulations.qp import StepQP
from wuerfel_cvx.scaling import scaled_qp, unknowns_scale, weights_scale
from wuerfel_cvx.solve import VERIFY_FACTOR, solve_step_qp
from wuerfel_cvx.solvers import SOLVERS, TOLERANCE_PRESETS

HIGH = TOLERANCE_PRESETS["high"]
DIRECT_SOLVERS = [name for name, spec in SOLVERS.items() if spec.backend is not None]
pytestmark = [pytest.mark.integration, pytest.mark.filterwarnings(  # cvxpy reading its own
    "ignore:Reading from a sparse CVXPY expression:RuntimeWarning")]  # sparse parameters


def direct_for(solver: str, qp: StepQP, options: dict[str, Any],
               names: dict[int, str] | None = None) -> DirectSolver | None:
    """``solver``'s direct path for ``qp``'s freshly compiled structure."""
    compiled = CompiledQP.of(qp)
    declared = compiled.load(qp)
    backend = SOLVERS[solver].backend
    assert backend is not None
    return build_direct(solver, backend, declared.problem,
                        compiled.parameter_names() if names is None else names, qp, options)


def test_the_solvers_with_a_direct_backend() -> None:
    assert DIRECT_SOLVERS == ["CLARABEL", "OSQP", "PIQP"]


@pytest.mark.parametrize("solver", list(DIRECT_SOLVERS))
def test_direct_path_matches_problem_solve_on_every_bank_qp(solver: str) -> None:
    options = SOLVERS[solver].options(HIGH)
    for entry in qp_bank():
        qp = entry.build()
        compiled = CompiledQP.of(qp)
        declared = compiled.load(qp)
        backend = SOLVERS[solver].backend
        assert backend is not None
        direct = build_direct(solver, backend, declared.problem, compiled.parameter_names(), qp,
                              options)
        assert direct is not None, entry.label
        fresh = solve_step_qp(entry.build(), solver, "high")
        result = direct.solve(qp, options)
        assert result.status == "optimal"
        assert np.max(np.abs(result.x - fresh.x)) <= AGREEMENT, entry.label
        # The duals read through the row map satisfy our own KKT conditions: a wrong row
        # or sign would leave a stationarity residual of the size of the contact forces.
        declared.problem.solve(solver=solver, warm_start=False, **options)
        if qp.n_inequalities:
            assert declared.ineq_constraint is not None
            np.testing.assert_allclose(result.ineq_dual, declared.ineq_constraint.dual_value,
                                       rtol=0, atol=1e-4 * (1 + np.abs(result.ineq_dual).max()))
        if qp.n_equalities:
            assert declared.eq_constraint is not None
            np.testing.assert_allclose(result.eq_dual, declared.eq_constraint.dual_value,
                                       rtol=0, atol=1e-4 * (1 + np.abs(result.eq_dual).max()))


@pytest.mark.parametrize("solver", list(DIRECT_SOLVERS))
def test_direct_solutions_pass_the_residual_check(solver: str) -> None:
    cache = CompiledQPCache(compile_after=1)
    for entry in qp_bank():
        solve_step_qp(entry.build(), solver, "high", cache=cache)  # compiles
        solution = solve_step_qp(entry.build(), solver, "high", cache=cache)  # direct
        qp = entry.build()
        seen = scaled_qp(qp, unknowns_scale(qp), weights_scale(qp))  # what the solver saw
        assert cache.direct_solver(seen, solver, SOLVERS[solver].options(HIGH)) is not None
        assert solution.verified, (entry.label, solution.residuals)
        assert solution.residuals.worst() <= VERIFY_FACTOR * HIGH


@pytest.mark.parametrize("solver", list(DIRECT_SOLVERS))
def test_unknown_parameters_fall_back_to_problem_solve_with_a_warning(
        solver: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_cvxpy, "_warned", set())
    qp = qp_bank()[0].build()
    with pytest.warns(DirectPathWarning, match="no step-QP slot"):
        assert direct_for(solver, qp, SOLVERS[solver].options(HIGH), names={}) is None
    with warnings.catch_warnings():
        warnings.simplefilter("error", DirectPathWarning)  # once per solver and reason
        assert direct_for(solver, qp, SOLVERS[solver].options(HIGH), names={}) is None


@pytest.mark.parametrize("solver", list(DIRECT_SOLVERS))
def test_an_untested_cvxpy_falls_back_to_problem_solve(
        solver: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_cvxpy, "_warned", set())
    monkeypatch.setattr(_cvxpy, "TESTED_CVXPY", ((0, 1), (0, 2)))
    cache = CompiledQPCache(compile_after=1)
    qp = qp_bank()[0].build()
    solve_step_qp(qp, solver, "high", cache=cache)  # compiles
    with pytest.warns(DirectPathWarning, match="outside the tested"):
        solution = solve_step_qp(qp_bank()[0].build(), solver, "high", cache=cache)
    assert solution.path == "compiled" and solution.verified


def test_the_installed_cvxpy_is_one_the_adapter_was_checked_against() -> None:
    _cvxpy.check_version()  # raises Unavailable otherwise


@pytest.mark.parametrize("solver", list(DIRECT_SOLVERS))
def test_internals_not_as_expected_fall_back_with_a_warning(
        solver: str, monkeypatch: pytest.MonkeyPatch) -> None:
    qp = qp_bank()[0].build()  # first: building the bank runs simulations, which would warn
    monkeypatch.setattr(_cvxpy, "_warned", set())

    def changed(*args: Any, **kwargs: Any) -> Any:
        raise AttributeError("'Problem' object has no attribute '_cache'")

    monkeypatch.setattr(_cvxpy, "_parameter_map", changed)
    with pytest.warns(DirectPathWarning, match="AttributeError"):
        assert direct_for(solver, qp, SOLVERS[solver].options(HIGH)) is None


@pytest.mark.parametrize("solver", list(DIRECT_SOLVERS))
def test_simulation_on_the_direct_path_equals_the_fresh_one(solver: str) -> None:
    steps = 100
    direct = simulate("tilted-drop", steps=steps, solver=solver, tol="high")
    fresh = simulate("tilted-drop", steps=steps, solver=solver, tol="high", compiled=False)
    assert direct.info["steps_reusing_a_compiled_structure"] > steps // 2
    assert direct.metrics["verified"].all()
    # Each step's velocities agree within AGREEMENT (m/s, from the "high" tolerance), and
    # a step of 0.01 s moves the points by 0.01 s times them: after ``steps`` steps the
    # points may differ by ``steps * 0.01 s * AGREEMENT``.
    np.testing.assert_allclose(direct.points, fresh.points, rtol=0,
                               atol=steps * 0.01 * AGREEMENT)


DIRECT_CLASSES = {"OSQP": DirectOSQP, "PIQP": DirectPIQP, "CLARABEL": DirectClarabel}


@pytest.mark.parametrize("solver", list(DIRECT_CLASSES))
def test_direct_path_raising_becomes_a_step_failure(solver: str,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    def explode(self: Any, *args: Any, **kwargs: Any) -> Any:
        raise RuntimeError("direct solver exploded")

    monkeypatch.setattr(DIRECT_CLASSES[solver], "solve", explode)
    with pytest.raises(StepFailure) as caught:
        simulate("stack-3", steps=5, solver=solver)
    # Step 1 is declared plainly, step 2 compiles the structure, step 3 is the first on
    # the direct path.
    assert (caught.value.step, caught.value.solver, caught.value.status) == (
        3, solver, "exception")
    assert "direct solver exploded" in caught.value.detail


def test_piqp_direct_path_takes_new_settings_and_reports_its_status(
        monkeypatch: pytest.MonkeyPatch) -> None:
    cache = CompiledQPCache(compile_after=1)
    entry = qp_bank()[0]
    solve_step_qp(entry.build(), "PIQP", "high", cache=cache)  # compiles, through cvxpy
    assert solve_step_qp(entry.build(), "PIQP", "high", cache=cache).verified  # direct
    spec = SOLVERS["PIQP"]
    starved = dataclasses.replace(spec, options=lambda eps: {**spec.options(eps), "max_iter": 1})
    monkeypatch.setitem(SOLVERS, "PIQP", starved)
    with pytest.raises(StepFailure) as caught:
        solve_step_qp(entry.build(), "PIQP", "high", step=7, cache=cache)
    assert cache.direct_solver(entry.build(), "PIQP", starved.options(HIGH)) is not None
    # One interior-point iteration cannot reach 1e-9: PIQP stops at its iteration limit.
    assert (caught.value.step, caught.value.solver, caught.value.status) == (
        7, "PIQP", "user_limit")


def test_piqp_direct_results_are_not_overwritten_by_the_next_solve() -> None:
    # PIQP's result arrays are views of the solver's memory, which its next solve reuses.
    options = SOLVERS["PIQP"].options(HIGH)
    qp = next(e.build() for e in qp_bank() if e.build().n_inequalities)
    direct = direct_for("PIQP", qp, options)
    assert direct is not None
    first = direct.solve(qp, options)
    kept = (first.x.copy(), first.eq_dual.copy(), first.ineq_dual.copy())
    moved = dataclasses.replace(qp, target=qp.target + 0.5, _declared=None)
    second = direct.solve(moved, options)
    assert np.max(np.abs(second.x - first.x)) > 0.1  # a different solution...
    for before, after in zip(kept, (first.x, first.eq_dual, first.ineq_dual), strict=True):
        np.testing.assert_array_equal(before, after)  # ...and the first one intact



class _TimedNativeCalls:
    """A native solver whose ``update`` and ``solve`` calls are timed (wall, s)."""

    def __init__(self, native: Any) -> None:
        self.native, self.seconds = native, 0.0

    def __getattr__(self, name: str) -> Any:
        attribute = getattr(self.native, name)
        if name not in ("update", "solve"):
            return attribute

        def timed(*args: Any, **kwargs: Any) -> Any:
            started = time.perf_counter()
            try:
                return attribute(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - started
        return timed


@pytest.mark.parametrize("solver", list(DIRECT_SOLVERS))
def test_direct_solver_time_is_at_most_the_wall_time_of_the_native_calls(solver: str) -> None:
    # The native time is the wall time of the native calls (one clock, nested intervals:
    # inside the direct solve, around the calls themselves), and the solver time is at most
    # that.  Clarabel's own solve_time alone broke this (it read above the calls).
    options = SOLVERS[solver].options(HIGH)
    for entry in qp_bank():
        qp = entry.build()
        direct = direct_for(solver, qp, options)
        assert direct is not None
        native = _TimedNativeCalls(direct.solver)
        direct.solver = native
        started = time.perf_counter()
        result = direct.solve(qp, options)
        outer = time.perf_counter() - started
        assert native.seconds <= result.native_time <= outer
        solver_time = SOLVERS[solver].timing.solver_time(result.reported_time,
                                                         result.native_time)
        assert solver_time == min(result.native_time, result.reported_time) > 0.0
