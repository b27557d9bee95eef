"""Injected solver faults: each ends in a clear StepFailure or a recorded fallback.

Extends tests/test_solver_failures.py (OSQP's iteration limit, exceptions raised by
cvxpy and the direct path) with: the iteration limit of the other solvers, an
infeasible step, NaN data, NaN multipliers, the ``fallback`` solvers of
:func:`wuerfel_cvx.simulate` and ``--fallback``, and the partial run the command
line saves for every kind of fault.
"""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path
from typing import Any

import cvxpy as cp
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.optimize import linprog

import wuerfel_cvx.solve.cvxpy_forms as cvxpy_forms
from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.cli import main
from wuerfel_cvx.errors import InputError, StepFailure
from wuerfel_cvx.formulations import StepQP, step_qp
from wuerfel_cvx.formulations.velocity import VelocityFormulation
from wuerfel_cvx.lab.robustness.faults import SQUEEZED_SCENE, NaNInQP, clarabel_raises
from wuerfel_cvx.scenes.scene import Square, Table
from wuerfel_cvx.solve import registry as solvers
from wuerfel_cvx.solve.paths import VERIFY_FACTOR, Residuals, SolvePath, solve_step_qp
from wuerfel_cvx.solve.registry import TOLERANCE_PRESETS, available_solvers
from wuerfel_cvx.step.model import Model, State
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

# the package exports the function simulate, which shadows the module's attribute name
simulation_module = importlib.import_module("wuerfel_cvx.step.simulation")

SCENE = "stack-3"  # every square touches its neighbour or the floor from step 1

SQUEEZED = SQUEEZED_SCENE

SQUEEZED_TOML = """\
allow_overlap = true
[[squares]]
center = [0.0, 0.5]
[[tables]]
center = [-0.9, 0.5]
size = [1.0, 3.0]
[[tables]]
center = [0.9, 0.5]
size = [1.0, 3.0]
"""


def limit_iterations(monkeypatch: pytest.MonkeyPatch, solver: str, from_call: int,
                     options: dict[str, Any]) -> None:
    """Give ``solver`` ``options`` on top of its own from solve call ``from_call`` on."""
    spec = solvers.SOLVERS[solver]
    calls = {"n": 0}

    def patched(eps: float) -> dict[str, Any]:
        calls["n"] += 1
        return {**spec.options(eps), **options} if calls["n"] >= from_call else spec.options(eps)

    monkeypatch.setitem(solvers.SOLVERS, solver, dataclasses.replace(spec, options=patched))


def assert_clean_partial(traj: Trajectory, n_steps: int) -> None:
    """A cut-short run: ``n_steps`` good steps, all finite, every stored step solved."""
    assert traj.n_steps == n_steps == len(traj.metrics)
    assert np.all(np.isfinite(traj.points)) and np.all(np.isfinite(traj.velocities))
    assert set(traj.metrics["status"]) <= {cp.OPTIMAL, cp.OPTIMAL_INACCURATE}


# ------------------------------------------------------------------ iteration limit
#: One iteration cannot meet the default tolerance; what each solver then reports
#: (checked by running it).  SCS returns an 'optimal_inaccurate' answer that the
#: residual check rejects (with polishing off: its active set, polished, can be exact).
#: OSQP is in test_solver_failures.py.
ONE_ITERATION: dict[str, tuple[dict[str, Any], str]] = {
    "CLARABEL": ({"max_iter": 1}, cp.USER_LIMIT),
    "PIQP": ({"max_iter": 1}, cp.USER_LIMIT),
    "PROXQP": ({"max_iter": 1}, cp.USER_LIMIT),
    "SCS": ({"max_iters": 1}, cp.OPTIMAL_INACCURATE),
    "DAQP": ({"iter_limit": 1}, cp.USER_LIMIT),
}


@pytest.mark.parametrize("solver", [s for s in ONE_ITERATION if s in available_solvers()])
def test_one_iteration_is_a_step_failure_naming_step_solver_status(
        monkeypatch: pytest.MonkeyPatch, solver: str) -> None:
    options, status = ONE_ITERATION[solver]
    limit_iterations(monkeypatch, solver, 3, options)
    with pytest.raises(StepFailure) as caught:  # cold: from a warm start one may suffice
        simulate(SCENE, dt=0.01, steps=5, solver=solver, warm_start=False, polish=False)
    failure = caught.value
    assert (failure.step, failure.solver, failure.status) == (3, solver, status)
    assert f"step 3: solver {solver} failed with status '{status}'" in str(failure)
    assert_clean_partial(failure.trajectory, 2)


def test_fallback_solver_takes_over_a_failed_step_and_is_recorded(
        monkeypatch: pytest.MonkeyPatch) -> None:
    limit_iterations(monkeypatch, "OSQP", 3, {"max_iter": 1, "warm_start": False,
                                              solvers._osqp_polish_option(): False,
                                              "eps_abs": 1e-12, "eps_rel": 1e-12})
    traj = simulate(SCENE, dt=0.01, steps=5, solver="osqp", fallback=("clarabel",))
    m = traj.metrics
    assert traj.n_steps == 5
    assert list(m["solver"]) == ["OSQP", "OSQP", "CLARABEL", "CLARABEL", "CLARABEL"]
    assert list(m["status"]) == [cp.OPTIMAL] * 5
    assert list(m["primary_status"]) == [cp.OPTIMAL] * 2 + [cp.USER_LIMIT] * 3
    assert m["verified"].all()
    assert traj.info["solver"] == "OSQP" and traj.info["fallback"] == ["CLARABEL"]
    # The stack is at rest, and stays so whichever solver solves a step: within the
    # default tolerance (1e-7 m/s on velocities, times 5 steps of 0.01 s) of its start.
    np.testing.assert_allclose(traj.points[-1], traj.points[0], rtol=0, atol=1e-8)


def test_unknown_fallback_solver_is_an_input_error() -> None:
    with pytest.raises(InputError, match="unknown solver 'nosuch'"):
        simulate(SCENE, steps=1, fallback=("nosuch",))


# ------------------------------------------------------------------ infeasible step
def squeezed_qp(beta: float, push_speed: float) -> StepQP:
    model = Model.from_scene(SQUEEZED)
    formulation = VelocityFormulation(beta=beta, push_speed=push_speed)
    return step_qp(formulation, model, State.initial(SQUEEZED), 0.01)


def test_overlap_without_stabilisation_is_not_infeasible() -> None:
    """Without push-out the zero velocity satisfies every row, so no overlap is infeasible.

    Rods ask ``(d/l).(v_i - v_j) = -(beta/dt) C/l = 0`` with ``beta = 0``.  With the
    start rows a point inside a body asks ``grad . v >= -(beta/dt) * distance = 0``; with
    the closest-approach rows and ``push_speed = 0`` its ramp is flat at its depth, so
    both of its rows ask ``>= 0``.  A point outside asks at most ``>= 0`` either way.
    """
    off = (VelocityFormulation(beta=0.0, linearisation="start"),
           VelocityFormulation(beta=0.0, push_speed=0.0))
    for scene in (SQUEEZED, Scene.named("overlap-recovery")):
        model = Model.from_scene(scene)
        for formulation in off:
            qp = step_qp(formulation, model, State.initial(scene), 0.01)
            assert np.all(qp.eq_rhs == 0.0) and np.all(qp.ineq_rhs <= 0.0)
            assert np.any(qp.ineq_rhs == 0.0)  # there are penetrating corners
            traj = simulate(scene, dt=0.01, steps=3, formulation=formulation)
            assert traj.metrics["verified"].all()


def test_squeezed_square_is_truly_infeasible() -> None:
    """Independent of the QP solvers: HiGHS finds no point of ``E x = e, G x >= h``.

    The walls push the left corners right and the right corners left (push-out at up to
    1 m/s), while the rods keep the square rigid: no velocity does both.
    """
    qp = squeezed_qp(0.2, 1.0)
    result = linprog(np.zeros(qp.n_variables), A_ub=-sp.csr_array(qp.ineq_matrix),
                     b_ub=-qp.ineq_rhs, A_eq=qp.eq_matrix, b_eq=qp.eq_rhs,
                     bounds=(None, None), method="highs")
    assert result.status == 2  # infeasible
    relaxed = squeezed_qp(0.0, 0.0)
    result = linprog(np.zeros(relaxed.n_variables), A_ub=-sp.csr_array(relaxed.ineq_matrix),
                     b_ub=-relaxed.ineq_rhs, A_eq=relaxed.eq_matrix, b_eq=relaxed.eq_rhs,
                     bounds=(None, None), method="highs")
    assert result.status == 0  # the same rows without stabilisation are feasible


#: What a solver that cannot say "infeasible" reports on the squeezed square, and why.
NO_INFEASIBILITY_CLAIM = {
    "PROXQP": cp.USER_LIMIT,  # its primal certificate test is off (NO_PRIMAL_CERTIFICATE)
}


@pytest.mark.parametrize("solver", available_solvers())
def test_infeasible_step_is_a_step_failure_for_every_solver(solver: str) -> None:
    with pytest.raises(StepFailure) as caught:
        simulate(SQUEEZED, dt=0.01, steps=3, solver=solver)
    failure = caught.value
    assert (failure.step, failure.solver) == (1, solver)
    assert ("infeasible" in failure.status if solver not in NO_INFEASIBILITY_CLAIM
            else failure.status == NO_INFEASIBILITY_CLAIM[solver])
    assert failure.trajectory.n_steps == 0
    np.testing.assert_array_equal(failure.trajectory.points[0], SQUEEZED.initial_points())


def test_fallback_that_also_fails_names_every_solver() -> None:
    with pytest.raises(StepFailure) as caught:
        simulate(SQUEEZED, steps=2, solver="clarabel", fallback=("osqp",))
    failure = caught.value
    assert (failure.step, failure.solver, failure.status) == (1, "CLARABEL", cp.INFEASIBLE)
    assert "then OSQP failed with 'infeasible'" in str(failure)
    assert failure.trajectory.n_steps == 0


def test_no_false_infeasible_at_extreme_speed() -> None:
    """A unit square at 1e6 m/s (the speed limit) over a table: no false 'infeasible'.

    CLARABEL called such a step infeasible; solved in scaled units it returns an optimum
    (``wuerfel_cvx.solve.scaling``), so the fallback is not needed.  Its multipliers on the
    inactive rows (slack of order 1e2 m/s beside targets of 1e6 m/s) leave a relative
    complementarity residual of 3e-4 at ``default``, above the check's bound: that step is
    recorded as unverified, not hidden.  OSQP verifies the same QP.
    """
    scene = Scene("fast", (Square(center=(0.0, 2.0), velocity=(1e6, 0.0)),),
                  (Table(center=(0.0, -0.5), size=(20.0, 1.0)),))
    traj = simulate(scene, dt=0.01, steps=2, solver="clarabel", fallback=("osqp",))
    m = traj.metrics
    assert np.all(np.isfinite(traj.points))
    assert (m["primary_status"] == cp.OPTIMAL).all() and (m["solver"] == "CLARABEL").all()
    for verified, complementarity in zip(m["verified"], m["complementarity"], strict=True):
        assert verified or complementarity > VERIFY_FACTOR * TOLERANCE_PRESETS["default"]
    assert m["verified"].iloc[1]  # in free flight, out of every contact's reach
    assert simulate(scene, dt=0.01, steps=2, solver="osqp").metrics["verified"].all()


# ------------------------------------------------------------------ NaN data
@dataclasses.dataclass(frozen=True)
class NaNState(VelocityFormulation):
    """The velocity formulation, advancing to a NaN velocity in step ``bad_step``."""

    bad_step: int = 2
    advanced: list[int] = dataclasses.field(default_factory=lambda: [0])

    def advance(self, model: Model, state: State, solution: Any, dt: float) -> State:
        """The moved state, with a NaN velocity after step ``bad_step``."""
        moved = super().advance(model, state, solution, dt)
        self.advanced[0] += 1
        if self.advanced[0] == self.bad_step:
            moved.velocities[0, 0] = np.nan
        return moved


@pytest.mark.parametrize("solver", ["CLARABEL", "OSQP", "PIQP"])
@pytest.mark.parametrize("array", ["target", "eq_rhs", "ineq_rhs"])
def test_nan_in_the_qp_data_stops_before_any_solver(solver: str, array: str) -> None:
    # step 3: CLARABEL and OSQP solve it on the direct path, where NaN once escaped as a
    # bare ValueError ("Parameter value must be real") without the trajectory
    with pytest.raises(StepFailure) as caught:
        simulate(SCENE, steps=5, solver=solver, formulation=NaNInQP(array=array),
                 fallback=("SCS",) if "SCS" in available_solvers() else ())
    failure = caught.value
    assert (failure.step, failure.solver, failure.status) == (3, solver, "invalid_data")
    assert f"non-finite {array}" in str(failure)
    assert "then" not in str(failure)  # no fallback is tried on the same bad data
    assert_clean_partial(failure.trajectory, 2)


def test_non_finite_state_is_not_stored() -> None:
    with pytest.raises(StepFailure) as caught:
        simulate(SCENE, steps=4, formulation=NaNState())
    failure = caught.value
    assert failure.step == 2 and "non-finite state" in str(failure)
    assert_clean_partial(failure.trajectory, 1)


def test_nan_residual_is_never_below_a_bound() -> None:
    assert Residuals(0.0, np.nan, 0.0).worst() == np.inf
    assert Residuals(np.nan, 0.0, 0.0).worst() == np.inf
    assert Residuals(1e-3, 2e-3, 0.0).worst() == 2e-3


def test_nan_multipliers_make_a_step_unverified(monkeypatch: pytest.MonkeyPatch) -> None:
    """Before, ``max(primal, nan, nan)`` was ``primal``: a NaN dual passed the check."""
    model = Model.from_scene(Scene.named(SCENE))
    qp = step_qp(VelocityFormulation(), model, State.initial(Scene.named(SCENE)), 0.01)
    assert solve_step_qp(qp, "CLARABEL").verified
    monkeypatch.setattr(cvxpy_forms, "_dual", lambda constraint, size: np.full(size, np.nan))
    solution = solve_step_qp(qp, "CLARABEL", path=SolvePath("declared"))  # through _dual
    assert solution.status == cp.OPTIMAL and not solution.verified
    assert solution.residuals.worst() == np.inf


# ------------------------------------------------------------------ exceptions
def test_exception_while_applying_compiled_parameters_is_a_step_failure(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from wuerfel_cvx.solve.cvxpy_forms import CompiledQP

    original = CompiledQP.load
    calls = {"n": 0}

    def load(self: CompiledQP, *args: Any, **kwargs: Any) -> Any:
        calls["n"] += 1
        if calls["n"] == 2:  # step 1 is declared, step 2 compiles, step 3 reloads
            raise ValueError("Parameter value must be real.")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(CompiledQP, "load", load)
    with pytest.raises(StepFailure) as caught:
        simulate(SCENE, steps=5, solve_path="compiled")
    assert (caught.value.step, caught.value.status) == (3, "exception")
    assert "Parameter value must be real" in str(caught.value)
    assert_clean_partial(caught.value.trajectory, 2)


def test_fallback_takes_over_from_a_raising_solver(monkeypatch: pytest.MonkeyPatch) -> None:
    with clarabel_raises():  # from step 2 on: each update of CLARABEL's native solver
        traj = simulate(SCENE, steps=4, fallback=("OSQP",))
    assert list(traj.metrics["primary_status"]) == ["optimal", "exception", "exception",
                                                    "exception"]
    assert list(traj.metrics["solver"]) == ["CLARABEL", "OSQP", "OSQP", "OSQP"]


# ------------------------------------------------------------------ command line
def _inject_nan(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(simulation_module, "get_formulation", lambda name: NaNInQP())


def _inject_exception(monkeypatch: pytest.MonkeyPatch) -> None:
    from wuerfel_cvx.solve.adapters.clarabel import ClarabelAdapter

    def explode(self: ClarabelAdapter, data: Any) -> None:  # an update in place: step 2 on
        raise RuntimeError("native solver exploded")

    monkeypatch.setattr(ClarabelAdapter, "_update", explode)


def _inject_iteration_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    limit_iterations(monkeypatch, "CLARABEL", 3, {"max_iter": 1})


#: fault -> (injection, scene file content or None for SCENE, failed step, status)
CLI_FAULTS: dict[str, tuple[Any, str | None, int, str]] = {
    "iteration limit": (_inject_iteration_limit, None, 3, cp.USER_LIMIT),
    "infeasible": (None, SQUEEZED_TOML, 1, cp.INFEASIBLE),
    "nan data": (_inject_nan, None, 3, "invalid_data"),
    "exception": (_inject_exception, None, 2, "exception"),
}


@pytest.mark.parametrize("fault", list(CLI_FAULTS))
def test_cli_saves_a_loadable_partial_run_for_every_fault(
        fault: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    inject, toml, step, status = CLI_FAULTS[fault]
    if inject is not None:
        inject(monkeypatch)
    scene = SCENE
    if toml is not None:
        (tmp_path / "scene.toml").write_text(toml)
        scene = str(tmp_path / "scene.toml")
    out = tmp_path / "partial"
    assert main(["simulate", scene, "--steps", "5", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err
    first, second = err.strip().splitlines()
    assert f"step {step}: solver CLARABEL failed with status '{status}'" in first
    kept = step - 1
    assert f"saved the {kept} {'step' if kept == 1 else 'steps'} before it" in second
    loaded = Trajectory.load(tmp_path / "partial.npz")
    assert loaded.n_steps == step - 1 == len(loaded.metrics)
    assert np.all(np.isfinite(loaded.points))


def test_cli_fallback_completes_the_run_and_says_so(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    _inject_iteration_limit(monkeypatch)
    out = tmp_path / "run"
    assert main(["simulate", SCENE, "--steps", "4", "--fallback", "osqp", "--out",
                 str(out)]) == 0
    printed = capsys.readouterr().out
    assert "fallback             2 steps solved by OSQP after CLARABEL failed" in printed
    loaded = Trajectory.load(tmp_path / "run.npz")
    assert list(loaded.metrics["primary_status"]) == ["optimal"] * 2 + [cp.USER_LIMIT] * 2
    assert list(loaded.metrics["solver"]) == ["CLARABEL"] * 2 + ["OSQP"] * 2
    assert loaded.info["fallback"] == ["OSQP"]


def test_fallback_takes_over_island_by_island(monkeypatch: pytest.MonkeyPatch,
                                             two_stacks_and_a_faller: Scene) -> None:
    with clarabel_raises():
        traj = simulate(two_stacks_and_a_faller, steps=6, islands=True, fallback=("OSQP",))
    m = traj.metrics
    assert traj.n_steps == 6 and m["verified"].all()
    # An island QP whose structure CLARABEL's native solver has seen raises (an update in
    # place) and OSQP solves it; an island QP of a new structure stays CLARABEL's.  The
    # row names every solver that produced the step.
    rescued = m["primary_status"] == "exception"
    assert rescued.any()
    assert m.loc[rescued, "solver"].str.contains("OSQP").all()
    assert (m.loc[~rescued, "solver"] == "CLARABEL").all()
    assert (m["status"] == cp.OPTIMAL).all()


def test_cli_animates_the_partial_run_of_a_failed_step(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    from PIL import Image

    _inject_iteration_limit(monkeypatch)  # fails at step 3
    out = tmp_path / "partial.gif"
    assert main(["simulate", SCENE, "--steps", "5", "--fps", "100", "--animate",
                 str(out)]) == 1
    err = capsys.readouterr().err
    assert "Traceback" not in err and f"animated the 2 steps before it in {out}" in err
    with Image.open(out) as image:
        assert image.n_frames == 3  # the states at 0, 0.01 and 0.02 s
