"""The floor under call / solver: a run's solver calls captured and replayed bare."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.lab.bench import runner
from wuerfel_cvx.lab.bench.floors import bare_calls, captured_calls, replay
from wuerfel_cvx.lab.bench.suite import Suite
from wuerfel_cvx.scenes.scene import Scene
from wuerfel_cvx.settings import Settings
from wuerfel_cvx.solve.registry import available_solvers

pytestmark = pytest.mark.integration

STEPS = 40
"""Long enough for tilted-drop to land (contacts, a second structure) at dt 0.01 s."""


@pytest.mark.parametrize("solver", ["CLARABEL", "OSQP", "PIQP"])
def test_the_capture_holds_the_qps_the_run_solved_in_order(solver: str) -> None:
    scene = Scene.named("tilted-drop")
    calls, done = captured_calls(scene, Settings(solver=solver), STEPS)
    run = simulate(scene, steps=STEPS, solver=solver)
    assert done == STEPS
    assert len(calls) == int(run.metrics["passes"].sum())  # every pass, one call each
    # the calls' QPs are the run's (ordinary data: the solver saw the QP itself), so the
    # replayed answers are the run's solver answers: the same sizes step by step
    sizes = [call.qp.n_inequalities for call in calls]
    assert sizes[-1] == run.metrics["n_inequalities"].iloc[-1]
    assert all(call.spec.name == solver for call in calls)


def test_the_replay_times_every_call_and_the_floor_is_at_least_the_solver() -> None:
    calls, done = captured_calls(Scene.named("tilted-drop"), Settings(solver="PIQP"), STEPS)
    floor = replay(calls, done, repeats=2)
    assert floor.calls == len(calls) and floor.steps == STEPS
    assert floor.call_seconds > 0 and floor.own_seconds > 0
    # the solver's own time is capped by the wall time of its calls (Timing.solver_time),
    # so no call's bare time is below its own: the ratio is at least 1
    assert floor.over_solver >= 1.0
    assert math.isclose(floor.per_step, floor.call_seconds / STEPS)


def test_a_solver_without_an_adapter_has_no_bare_floor() -> None:
    if "SCS" not in available_solvers():
        pytest.skip("SCS (no adapter: it goes through cvxpy) is not installed")
    floor = bare_calls(Scene.named("tilted-drop"), Settings(solver="SCS"), 5)
    assert math.isnan(floor.per_step) and math.isnan(floor.over_solver)


def test_a_suite_asks_for_the_floor_of_its_default_points_only() -> None:
    suite = Suite.from_dict({
        "name": "tiny", "defaults": {"duration": 0.05, "reference": "none",
                                     "compare_every": 0, "bare_call_floor": True},
        "grid": [{"scenes": ["tilted-drop"], "formulations": ["rigid", "velocity"],
                  "solvers": ["PIQP"]}]})
    rows = {point.formulation: runner.run_point(point, None) for point in suite.points}
    assert suite.points[0].runs_defaults != suite.points[1].runs_defaults
    default = Settings().formulation
    for formulation, row in rows.items():
        measured = np.isfinite(row["bare_call_over_solver"] or math.nan)
        assert measured == (formulation == default)
    assert rows[default]["bare_call_time_per_step"] > 0
