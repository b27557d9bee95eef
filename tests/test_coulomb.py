"""The Coulomb friction model (:mod:`wuerfel_cvx.friction.coulomb`).

Its two problems checked on their own, and the fixed point against the analytic slides of
a box on a slope and on a flat table.
"""

from __future__ import annotations

import dataclasses
import math
import types
import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from oracles import declared_friction
from wuerfel_cvx import simulate
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.formulations import StepQP, VelocityFormulation, get_formulation
from wuerfel_cvx.friction.coulomb import (
    ContactOutcome,
    CoulombNotConverged,
    CoulombSettings,
    CoulombStep,
    FrictionMemory,
    _twin_groups,
    _unchanged,
    fixed_point,
    with_friction_impulse,
)
from wuerfel_cvx.friction.problem import (
    FrictionProblem,
    QPSolve,
    friction_problem,
    friction_residuals,
    normal_impulses,
    solve_friction,
)
from wuerfel_cvx.scenes.scene import Scene, Square, Table
from wuerfel_cvx.solve.paths import (
    INVALID_DATA,
    SOLVE_PATHS,
    VERIFY_FACTOR,
    SolvePath,
    StepSolution,
    solve_step_qp,
    solve_with_fallback,
)
from wuerfel_cvx.solve.registry import available_solvers, tolerance_value
from wuerfel_cvx.step.contacts import ContactIndex, find_contacts
from wuerfel_cvx.step.model import Model, State
from wuerfel_cvx.step.simulation import Simulation
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.unit

G = 9.81
"""Gravity (m/s^2) of every scene."""
DT = 1.0 / 240.0
"""Time step (s) of the analytic tests (the issue's ramp target is at dt 1/240)."""
SOLVERS = ("CLARABEL", "OSQP", "PIQP")
EPS = tolerance_value("default")
CHECK = VERIFY_FACTOR * EPS
"""What the residual checks accept at the default tolerance."""


def slope(theta: float, mu: float) -> Scene:
    """A unit box resting on a table tilted by ``theta`` (rad), both with friction ``mu``."""
    normal = np.array([-math.sin(theta), math.cos(theta)])
    return Scene(name="slope",
                 squares=(Square(center=(0.5 * normal[0], 0.5 * normal[1]), size=1.0,
                                 angle=theta, friction=mu),),
                 tables=(Table(center=(-0.5 * normal[0], -0.5 * normal[1]), size=(40.0, 1.0),
                               angle=theta, friction=mu),))


def flat(v0: float, mu: float) -> Scene:
    """A unit box on a flat table, launched along it at ``v0`` (m/s)."""
    return Scene(name="flat",
                 squares=(Square(center=(0.0, 0.5), size=1.0, velocity=(v0, 0.0), friction=mu),),
                 tables=(Table(center=(0.0, -0.5), size=(40.0, 1.0), friction=mu),))


def along(traj: Trajectory, theta: float) -> tuple[np.ndarray, np.ndarray]:
    """The box centre's position along the slope and its height above the contact (m)."""
    centre = traj.points.reshape(len(traj.points), 4, 2).mean(axis=1)
    tangent = np.array([math.cos(theta), math.sin(theta)])
    normal = np.array([-math.sin(theta), math.cos(theta)])
    return centre @ tangent, centre @ normal - 0.5


def fitted_acceleration(traj: Trajectory, theta: float) -> float:
    """The acceleration (m/s^2) down the slope of a parabola fitted to the slide."""
    position, _ = along(traj, theta)
    coefficients = np.polyfit(traj.times, position, 2)
    return float(-2.0 * coefficients[0])


def sliding_qp(mu: float = 0.3, theta: float = 0.5, speed: float = 0.5,
               formulation: str = "velocity"):  # type: ignore[no-untyped-def]
    """The first contact QP of a box on a slope, sliding down at ``speed`` (coulomb rows)."""
    scene = slope(theta, mu)
    model = Model.from_scene(scene)
    start = State.initial(scene)
    tangent = np.array([math.cos(theta), math.sin(theta)])
    state = State(start.points, np.tile(-speed * tangent, (4, 1)))
    chosen = dataclasses.replace(get_formulation(formulation), friction_model="coulomb")
    contacts = find_contacts(model, state.points, chosen.body_reach(model, state, DT))
    return chosen.build(model, state, contacts, DT)


def test_the_fixed_impulse_enters_the_contact_qp_as_its_work() -> None:
    qp = sliding_qp()
    assert qp.cones is not None and len(qp.contacts) == 2
    friction = np.array([0.3, -0.7])
    shifted = with_friction_impulse(qp, friction)
    rng = np.random.default_rng(13)
    x = qp.target + 0.1 * rng.standard_normal(qp.n_variables)

    def difference(v: np.ndarray) -> float:
        """Shifted minus original objective: -2 lambda_t . S x plus a constant."""
        return float(np.sum(shifted.weights * (v - shifted.target) ** 2)
                     - np.sum(qp.weights * (v - qp.target) ** 2))

    step = 1e-6
    numeric = np.array([(difference(x + step * e) - difference(x - step * e)) / (2 * step)
                        for e in np.eye(qp.n_variables)])
    np.testing.assert_allclose(numeric, -2.0 * qp.cones.slip.T @ friction, atol=1e-6)
    # and the solved QP's stationarity in the original target carries 2 S' lambda_t
    solution = solve_step_qp(shifted, "CLARABEL")
    assert solution.verified
    eq_dual = np.linalg.lstsq(qp.eq_matrix.T.toarray(), (
        qp.ineq_matrix.T @ solution.ineq_dual - 2.0 * qp.weights * (solution.x - qp.target)
        + 2.0 * qp.cones.slip.T @ friction), rcond=None)[0]
    stationarity = (2.0 * qp.weights * (solution.x - qp.target) + qp.eq_matrix.T @ eq_dual
                    - qp.ineq_matrix.T @ solution.ineq_dual - 2.0 * qp.cones.slip.T @ friction)
    assert np.max(np.abs(stationarity)) < CHECK * (1.0 + np.max(np.abs(solution.ineq_dual)))


def solver_of(*solvers: str, step: int = 1, path: SolvePath | None = None,
              tol: str = "default") -> QPSolve:
    """A run's solve function: ``solvers`` (then fallbacks) at tolerance ``tol``."""
    def solve(qp: StepQP, *, repeated: bool = False) -> tuple[StepSolution, str]:
        return solve_with_fallback(qp, solvers, tol, step, path, repeated=repeated)

    return solve


def solved_friction_problem(solver: str = "CLARABEL"):  # type: ignore[no-untyped-def]
    qp = sliding_qp()
    solution = solve_step_qp(qp, "CLARABEL")
    problem = friction_problem(qp, solution, qp.target)
    return problem, solve_friction(problem, solver_of(solver), "default")


@pytest.mark.parametrize("solver", SOLVERS)
def test_the_friction_problem_gives_maximal_dissipation_at_the_cone_edge(solver: str) -> None:
    problem, answer = solved_friction_problem(solver)
    assert answer.verified and answer.residuals.worst() <= CHECK
    normal = problem.bound / 0.3
    np.testing.assert_allclose(normal.sum(), 1.0 * G * math.cos(0.5) * DT, rtol=1e-4)
    slip = problem.qp.cones.slip @ answer.x
    assert np.all(np.abs(slip) > 0.1)  # still sliding after one step
    # the impulse opposes the slip with its full Coulomb bound mu lambda_n
    np.testing.assert_allclose(-np.sign(slip) * answer.friction, problem.bound, rtol=1e-5,
                               atol=CHECK * np.max(problem.bound))


def friction_problems() -> dict[str, FrictionProblem]:
    """A few friction problems: sliding, sticking, with one or no contact with friction."""
    problems = {}
    for name, qp in {"sliding": sliding_qp(), "sticking": sliding_qp(mu=1.2, speed=0.0),
                     "rigid sliding": sliding_qp(formulation="rigid")}.items():
        problems[name] = friction_problem(qp, solve_step_qp(qp, "CLARABEL", "high"), qp.target)
    sliding = problems["sliding"]
    problems["one smooth contact"] = FrictionProblem(sliding.qp, sliding.target,
                                                     sliding.bound * np.array([1.0, 0.0]))
    problems["half bound"] = FrictionProblem(sliding.qp, sliding.target, 0.5 * sliding.bound)
    problems["no normal impulse"] = FrictionProblem(sliding.qp, sliding.target, 0 * sliding.bound)
    return problems


@pytest.mark.parametrize("solver", [name for name in (*SOLVERS, "PROXQP", "DAQP")
                                    if name in available_solvers()])  # extra solvers: if there
def test_the_friction_qp_solves_the_friction_problem_as_declared_in_cvxpy(solver: str) -> None:
    check_high = VERIFY_FACTOR * tolerance_value("high")
    for name, problem in friction_problems().items():
        # at the run's tolerance: verified, by the solver asked, friction residuals passed
        answer = solve_friction(problem, solver_of(solver), "default")
        assert answer.verified and answer.residuals.worst() <= CHECK, name
        assert answer.solver == solver, name  # no fallback took over
        # at the tight one: the answer of the problem as it was declared in cvxpy
        x, friction = declared_friction(problem, "CLARABEL", "high")
        tight = solve_friction(problem, solver_of(solver, tol="high"), "high")
        # the unknowns are unique (positive weights)
        assert np.max(np.abs(tight.x - x)) <= check_high * (1.0 + np.max(np.abs(x))), name
        if not np.any(problem.bound > 0.0):  # no slack: no impulse (cvxpy's is its noise)
            assert np.all(tight.friction == 0.0) and np.all(answer.friction == 0.0), name
            continue
        # so is the box's friction impulse, the sum over its contacts on one table edge (a
        # sticking box may share it between them in other ways, the rods taking the rest),
        # to what the KKT check's stationarity allows, check_high (1 + its terms)
        impulses = 1.0 + np.max(problem.bound)
        assert abs(np.sum(tight.friction - friction)) <= check_high * impulses, name
        # and where a contact slips, its impulse is -mu lambda_n sign(s) in both
        sliding = np.abs(problem.qp.cones.slip @ x) > 1e-3
        np.testing.assert_allclose(tight.friction[sliding], friction[sliding], rtol=1e-5,
                                   atol=check_high * np.max(problem.bound), err_msg=name)


@pytest.mark.parametrize("perturb", ["half impulse", "impulse along the slip",
                                     "impulse beyond the cone", "unknowns moved"])
def test_the_friction_check_catches_a_wrong_answer(perturb: str) -> None:
    problem, answer = solved_friction_problem()
    x, friction = answer.x.copy(), answer.friction.copy()
    if perturb == "half impulse":
        friction = 0.5 * friction
    elif perturb == "impulse along the slip":
        friction = -friction
    elif perturb == "impulse beyond the cone":
        friction = 1.1 * friction
    else:
        x = x + 1e-3
    residuals = friction_residuals(problem, x, friction, answer.eq_dual)
    assert residuals.worst() > 10.0 * CHECK  # well beyond what verification accepts


@pytest.mark.parametrize("path_name", SOLVE_PATHS)
def test_a_friction_problem_repeated_on_a_solve_path_gives_the_same_answer(
        path_name: str) -> None:
    # one structure three times: set up, then updated in place (native); declared, then
    # compiled on its second sighting (compiled); declared each time (declared).  Each in
    # a step of its own: a step's repeated structure is answered on its active set first
    problem, answer = solved_friction_problem()
    path = SolvePath(path_name)
    first = solve_friction(problem, solver_of("CLARABEL", path=path, step=1), "default")
    other = FrictionProblem(problem.qp, problem.target, 0.5 * problem.bound)
    updated = solve_friction(other, solver_of("CLARABEL", path=path, step=2), "default")
    again = solve_friction(problem, solver_of("CLARABEL", path=path, step=3), "default")
    counts = {"native": (1, 2, 0), "compiled": (0, 0, 1), "declared": (0, 0, 0)}[path_name]
    assert (path.native_setups, path.native_updates, path.compiled.compiled) == counts
    np.testing.assert_allclose(first.friction, answer.friction, rtol=1e-5,
                               atol=CHECK * np.max(problem.bound))
    np.testing.assert_allclose(updated.friction, 0.5 * answer.friction, rtol=1e-5)
    np.testing.assert_allclose(again.friction, answer.friction, rtol=1e-5,
                               atol=CHECK * np.max(problem.bound))
    assert first.verified and updated.verified and again.verified


def test_a_friction_problem_repeated_in_its_step_is_answered_on_its_active_set() -> None:
    # the fixed point's second friction problem of a step, its bounds changed a little (the
    # normal impulses of the next contact QP): no solver runs, and the answer is the one a
    # solver gives, to the check's accuracy
    problem, answer = solved_friction_problem()
    path = SolvePath()
    solve = solver_of("CLARABEL", path=path, step=4)
    first = solve_friction(problem, solve, "default")
    nearby = FrictionProblem(problem.qp, problem.target, 1.01 * problem.bound)
    repeated = solve_friction(nearby, solve, "default")
    assert (path.native_setups, path.native_updates, path.reused_active_sets) == (1, 0, 1)
    assert repeated.status == "optimal" and repeated.iterations == 0 and repeated.verified
    solved = solve_friction(nearby, solver_of("CLARABEL"), "default")
    np.testing.assert_allclose(repeated.friction, solved.friction, rtol=1e-5,
                               atol=CHECK * np.max(problem.bound))
    np.testing.assert_allclose(first.friction, answer.friction, rtol=1e-5,
                               atol=CHECK * np.max(problem.bound))


def test_a_failed_friction_problem_names_its_step_and_every_solver() -> None:
    problem, _ = solved_friction_problem()
    qp = problem.qp
    assert qp.n_equalities
    # the rods twice, the second time one of them 1 m/s apart: no x satisfies both
    contradiction = dataclasses.replace(
        qp, eq_matrix=sp.csr_array(sp.vstack([qp.eq_matrix, qp.eq_matrix[[0]]])),
        eq_rhs=np.append(qp.eq_rhs, qp.eq_rhs[0] + 1.0))
    broken = FrictionProblem(contradiction, problem.target, problem.bound)
    with pytest.raises(StepFailure) as caught:
        solve_friction(broken, solver_of("CLARABEL", "OSQP", step=7), "default")
    assert caught.value.step == 7 and caught.value.solver == "CLARABEL"
    assert "friction problem" in str(caught.value) and "then OSQP failed" in str(caught.value)


def test_a_friction_problem_with_non_finite_data_fails_before_any_solver() -> None:
    problem, _ = solved_friction_problem()
    broken = FrictionProblem(problem.qp, np.full_like(problem.target, np.nan), problem.bound)
    with pytest.raises(StepFailure) as caught:
        solve_friction(broken, solver_of("CLARABEL", "OSQP", step=7), "default")
    assert caught.value.step == 7 and caught.value.status == INVALID_DATA
    assert "friction problem: non-finite target" in str(caught.value)


def test_a_cone_violation_is_measured_even_where_stationarity_holds() -> None:
    problem, answer = solved_friction_problem()
    tighter = FrictionProblem(problem.qp, problem.target, 0.5 * problem.bound)
    residuals = friction_residuals(tighter, answer.x, answer.friction, answer.eq_dual)
    assert residuals.stationarity <= CHECK and residuals.cone > 10.0 * CHECK


def test_normal_impulses_are_the_multipliers_of_both_rows_of_a_contact() -> None:
    qp = sliding_qp()
    solution = solve_step_qp(qp, "CLARABEL")
    normal = normal_impulses(qp, solution.ineq_dual)
    assert normal.shape == (2,) and qp.n_inequalities == 4  # rate and approach rows
    np.testing.assert_allclose(normal, 0.5 * (solution.ineq_dual[:2] + solution.ineq_dual[2:]))


@pytest.mark.integration
@pytest.mark.parametrize("solver", SOLVERS)
def test_a_box_slides_down_a_slope_at_g_sin_minus_mu_cos(solver: str) -> None:
    theta, mu = 0.5, 0.3
    traj = simulate(slope(theta, mu), dt=DT, steps=60, solver=solver,
                    friction_model="coulomb")
    expected = G * (math.sin(theta) - mu * math.cos(theta))
    assert fitted_acceleration(traj, theta) == pytest.approx(expected, rel=0.01)
    metrics = traj.metrics
    assert metrics["verified"].all() and metrics["coulomb_converged"].all()
    assert metrics["coulomb_iterations"].max() <= VelocityFormulation().coulomb_max_iterations
    # no hover: the gap stays at the contact (the closest-approach acceptance), where the
    # ccp model would lift by mu |v_t| dt, about 1e-3 m at the end of this slide
    _, height = along(traj, theta)
    final_speed = expected * traj.times[-1]
    assert np.max(np.abs(height)) <= VelocityFormulation().gap_tolerance
    assert VelocityFormulation().gap_tolerance < 1e-2 * mu * final_speed * DT


@pytest.mark.integration
@pytest.mark.parametrize("formulation", ["velocity", "rigid"])
def test_a_box_sticks_when_mu_reaches_tan_theta(formulation: str) -> None:
    theta = 0.5
    mu = math.tan(theta) * 1.05
    traj = simulate(slope(theta, mu), dt=DT, steps=60, formulation=formulation,
                    friction_model="coulomb")
    position, _ = along(traj, theta)
    # static friction holds the box: what is left of the pull g sin(theta) is solver noise,
    # far below the 1 % of it that a slide would show in this time
    drift = np.max(np.abs(position - position[0]))
    assert drift < 0.01 * 0.5 * G * math.sin(theta) * traj.times[-1] ** 2
    assert traj.metrics["coulomb_converged"].all()


@pytest.mark.integration
def test_the_rigid_formulation_slides_as_the_velocity_one() -> None:
    theta, mu = 0.5, 0.3
    traj = simulate(slope(theta, mu), dt=DT, steps=60, formulation="rigid",
                    friction_model="coulomb")
    expected = G * (math.sin(theta) - mu * math.cos(theta))
    assert fitted_acceleration(traj, theta) == pytest.approx(expected, rel=0.01)


@pytest.mark.integration
def test_a_launched_box_stops_after_v0_squared_over_two_mu_g() -> None:
    v0, mu = 2.0, 0.5
    stop_time = v0 / (mu * G)
    steps = int(math.ceil(1.25 * stop_time / DT))
    traj = simulate(flat(v0, mu), dt=DT, steps=steps, friction_model="coulomb")
    centre = traj.points.reshape(len(traj.points), 4, 2).mean(axis=1)
    # the stop is resolved to one step: the distance to within v0 dt
    assert centre[-1, 0] - centre[0, 0] == pytest.approx(v0**2 / (2 * mu * G), abs=v0 * DT)
    speed = traj.velocities.reshape(len(traj.points), 4, 2).mean(axis=1)[:, 0]
    # at rest once stopped: no creep beyond the fixed point's tolerance.  It stops when the
    # normal impulse (m g dt) is settled to tol of itself, so the friction impulse, at most mu
    # times it, is settled to mu tol m g dt: a speed of mu tol g dt = 2e-6 m/s
    resting = mu * VelocityFormulation().coulomb_tolerance * G * DT
    moving = traj.times[np.abs(speed) > resting]
    assert moving.max() == pytest.approx(stop_time, abs=DT)
    assert traj.metrics["coulomb_converged"].all()


def test_mu_zero_is_the_frictionless_trajectory() -> None:
    # the table has friction, the box none: every contact mixes to mu = 0
    rough_table = Scene(name="flat", squares=(Square(center=(0.0, 0.5), size=1.0,
                                                     velocity=(2.0, 0.0)),),
                        tables=(Table(center=(0.0, -0.5), size=(40.0, 1.0), friction=0.5),))
    smooth = Scene(name="flat", squares=rough_table.squares,
                   tables=(Table(center=(0.0, -0.5), size=(40.0, 1.0)),))
    with_mu = simulate(rough_table, dt=DT, steps=10, friction_model="coulomb")
    without = simulate(smooth, dt=DT, steps=10)
    np.testing.assert_array_equal(with_mu.points, without.points)
    # a coulomb run with friction in the scene, but no fixed point was needed
    assert (with_mu.metrics["coulomb_iterations"] == 0).all()
    assert with_mu.metrics["coulomb_converged"].all()


def test_ccp_runs_leave_the_coulomb_columns_empty() -> None:
    traj = simulate(slope(0.5, 0.3), dt=DT, steps=2)
    assert traj.metrics["coulomb_iterations"].isna().all()
    assert traj.metrics["coulomb_converged"].isna().all()


def test_a_fixed_point_that_does_not_converge_is_reported_and_the_run_goes_on() -> None:
    # started from zero friction each step (no memory): with exact (polished) answers a
    # sticking square's fixed point started from the last step's impulses converges in one
    sim = Simulation(slope(0.5, 0.6), dt=DT, friction_model="coulomb",
                     formulation=dataclasses.replace(VelocityFormulation(),
                                                     coulomb_max_iterations=1,
                                                     coulomb_warm_start=False))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(3):
            record = sim.step()
    metrics = sim.trajectory().metrics
    assert not metrics["coulomb_converged"].any()
    assert (metrics["coulomb_iterations"] == 1).all()
    named = [str(w.message) for w in caught if issubclass(w.category, CoulombNotConverged)]
    assert [message.split(":")[0] for message in named] == ["step 1"]  # once per run
    assert "not converged: steps 1, 2, 3" in sim.trajectory().summary()
    # the last iterate's contact QP still met the gap acceptance
    assert metrics["penetration_m"].max() <= VelocityFormulation().gap_tolerance
    forces = record.coulomb_forces[0]
    assert forces is not None and forces.normal.shape == (2,)


@pytest.mark.integration
def test_the_card_house_fixed_point_converges_where_twin_contacts_split_their_load() -> None:
    # face-to-face cards: each card's corner on the other's edge, rows parallel to
    # 1 - cos < 1e-6, so the load's split between the twins is not unique; the iteration
    # moved it at a constant rate while the velocities settled, and a test on per-contact
    # normal impulses gave up steps 3 to 5 at 50 (reports/friction/coulomb-convergence.md)
    traj = simulate("card-house", dt=1.0 / 60.0, steps=5, solver="CLARABEL",
                    friction_model="coulomb")
    assert traj.metrics["coulomb_converged"].astype(bool).all()


def test_twin_contacts_share_a_load_group_and_others_do_not() -> None:
    # contacts 0 and 1 push along the same line (row 1 = 2 x row 0 + 1e-9: 1 - cos ~ 1e-19,
    # far below TWIN_PARALLEL); contact 2 has the opposite lever, so its row is not parallel to them
    rows = sp.csr_array(np.array([[0.0, 1.0, 0.5], [0.0, 2.0, 1.0 + 1e-9], [0.0, 1.0, -0.5]]))
    qp = types.SimpleNamespace(ineq_matrix=rows, contacts=[0, 1, 2],
                               cones=types.SimpleNamespace(row_contact=np.arange(3)))
    groups = _twin_groups(qp)  # type: ignore[arg-type]
    assert groups[0] == groups[1] != groups[2]


def test_a_load_moving_between_twins_is_no_change_of_the_contact_qp() -> None:
    # twins 0 and 1 carry 1 N s between them, split 0.7 / 0.3 and then 0.4 / 0.6 (each
    # contact's impulse moves by 0.15 of the largest); the bodies' motion moves by 1e-3 of
    # its largest, ten times the tolerance: only the twins' summed load says unchanged
    qp = types.SimpleNamespace(weights=np.ones(2), contacts=[0, 1, 2],
                               cones=types.SimpleNamespace(row_contact=np.arange(3)))
    twins, target = np.array([0, 0, 1]), np.zeros(2)

    def outcome(x: list[float], loads: list[float]) -> ContactOutcome:
        solution = types.SimpleNamespace(x=np.array(x), ineq_dual=2.0 * np.array(loads))
        return ContactOutcome.of(qp, solution, target, twins)  # type: ignore[arg-type]

    before, after = outcome([1.0, 0.5], [0.7, 0.3, 2.0]), outcome([1.001, 0.5], [0.4, 0.6, 2.0])
    assert _unchanged(after, before, 1e-4)
    assert not _unchanged(after, before.without_loads(), 1e-4)  # the contacts changed
    assert _unchanged(outcome([1.00001, 0.5], [0.4, 0.6, 2.0]), before.without_loads(), 1e-4)


def test_a_step_reports_its_contact_forces_inside_the_cone() -> None:
    sim = Simulation(slope(0.5, 0.3), dt=DT, friction_model="coulomb")
    sim.step()
    record = sim.step()
    (forces,) = record.coulomb_forces
    assert forces is not None
    np.testing.assert_allclose(forces.normal.sum(), G * math.cos(0.5) * DT, rtol=1e-3)
    tolerance = VelocityFormulation().coulomb_tolerance * np.max(forces.normal)
    assert np.all(np.abs(forces.friction) <= forces.coefficient * forces.normal + tolerance)
    assert np.all(np.abs(forces.slip) > 0.0)
    assert np.all(forces.friction * forces.slip < 0.0)  # opposes the slip



@pytest.mark.integration
@pytest.mark.parametrize("scene", [slope(0.4, 0.5), slope(0.5, 0.3)],
                         ids=["sticking", "sliding"])
def test_a_warm_started_fixed_point_moves_as_a_cold_one_in_fewer_iterations(
        scene: Scene) -> None:
    steps = 60
    runs = [simulate(scene, dt=DT, steps=steps,
                     formulation=VelocityFormulation(friction_model="coulomb",
                                                     coulomb_warm_start=warm))
            for warm in (False, True)]
    cold, warm = runs
    assert cold.metrics["coulomb_converged"].all() and warm.metrics["coulomb_converged"].all()
    # each run's friction impulse is settled to mu tol of the normal one (m g dt), a speed of
    # mu tol g dt per step; over T = steps dt the two may part by at most mu tol g T^2
    mu = max(body.friction for body in scene.squares)
    bound = mu * VelocityFormulation().coulomb_tolerance * G * (steps * DT) ** 2
    assert np.max(np.abs(warm.points - cold.points)) <= bound
    iterations = [int(run.metrics["coulomb_iterations"].sum()) for run in runs]
    assert iterations[1] < iterations[0]


def pushed_stack_fixed_point(tolerance: float, memory: int,
                             initial: np.ndarray | None = None) -> CoulombStep:
    """The first step's fixed point of a rough 3-stack whose top box is pushed at 0.5 m/s.

    At dt 1/60: the pushed box's friction, the boxes below held by theirs, settles through
    the stack slowly (the plain iteration's slowest case among small stacks).
    """
    scene = Scene(name="pushed-stack", squares=tuple(
        Square(center=(0.0, 0.5 + k), friction=0.6, velocity=(0.5 if k == 2 else 0.0, 0.0))
        for k in range(3)), tables=(Table(center=(0.0, -0.5), size=(40.0, 1.0), friction=0.6),))
    dt = 1.0 / 60.0
    model, state = Model.from_scene(scene), State.initial(scene)
    formulation = VelocityFormulation(friction_model="coulomb")
    contacts = find_contacts(model, state.points, formulation.body_reach(model, state, dt))
    qp = formulation.build(model, state, contacts, dt)
    return fixed_point(formulation, model, state, qp, dt, solver_of("CLARABEL"), "default",
                       CoulombSettings(500, tolerance, memory), initial)


@pytest.mark.integration
def test_the_accelerated_fixed_point_reaches_the_plain_ones_answer_in_fewer_iterations(
        ) -> None:
    tolerance = 1e-6  # tighter than the default 1e-4, so that the answers are compared closely
    plain, accelerated = (pushed_stack_fixed_point(tolerance, memory)
                          for memory in (0, CoulombSettings(1, 1.0).memory))
    assert plain.converged and accelerated.converged
    assert accelerated.iterations < plain.iterations
    # the accelerated answer is a fixed point of the plain iteration: started from its
    # friction impulses, the plain iteration accepts at its first test
    again = pushed_stack_fixed_point(tolerance, 0, accelerated.forces.friction)
    assert again.converged and again.iterations == 1
    # both near the fixed point: the test bounds successive iterates, not the distance to
    # the fixed point, which a contraction by rho leaves at up to rho / (1 - rho) times the
    # tolerance (the plain iteration's rho = tol^(1 / iterations) is 0.7 here, slower in its
    # tail: measured 3 and 11 tolerances); 20 tolerances of the largest normal impulse
    tight = pushed_stack_fixed_point(tolerance / 100.0, 0)
    scale = 20.0 * tolerance * float(np.max(tight.forces.normal))
    for answer in (plain, accelerated):
        assert np.max(np.abs(answer.forces.normal - tight.forces.normal)) <= scale
        assert np.max(np.abs(answer.forces.friction - tight.forces.friction)) <= scale


@pytest.mark.unit
def test_an_island_finds_the_impulses_its_contacts_had_in_the_whole_model() -> None:
    scene = dataclasses.replace(  # two boxes side by side on one table: two islands
        flat(0.0, 0.5), squares=(Square(center=(-2.0, 0.5), size=1.0, friction=0.5),
                                 Square(center=(2.0, 0.5), size=1.0, friction=0.5)))
    model = Model.from_scene(scene)
    state = State.initial(scene)
    contacts = find_contacts(model, state.points,
                             get_formulation("velocity").body_reach(model, state, DT))
    impulses = np.arange(1.0, len(contacts) + 1.0)
    memory = FrictionMemory(model.n_boxes, ContactIndex.of(contacts.ids()), impulses)
    second = np.array([1])
    island = contacts.restricted(second, model.n_boxes, model.n_tables)
    of_second = impulses[(contacts.point_body == 1) | (contacts.edge_body == 1)]
    assert len(island) == len(of_second) > 0
    np.testing.assert_array_equal(memory.initial(island, second), of_second)
    assert not np.any(memory.initial(island, None) == of_second)  # unmapped: wrong contacts
