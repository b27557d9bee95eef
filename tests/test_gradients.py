"""Gradients through a run (issue 26): the adjoint against finite differences and physics.

Cross-checks of :meth:`Trajectory.gradient` on the ``rigid`` formulation:

* central finite differences of a linear loss of the corners on smooth segments (no active
  set change, no contact at the speculative/Baumgarte switch): a slide, a tilted drop with
  its landing, a resting stack pushed sideways, for CLARABEL, OSQP and PIQP;
* the analytic slide: a box launched at ``v0`` on a table of friction ``mu`` stops after
  ``d = v0^2 / (2 mu g)``, so ``dd/dv0 = v0 / (mu g)`` and ``dd/dmu = -v0^2 / (2 mu^2 g)``.

Tolerance of the finite differences.  Each run's answers are polished to round-off, and a
run of 30-60 steps accumulates some 1e-13 m in the loss; with a step of ``1e-6`` the central
difference's round-off is about 1e-13 / 1e-6 = 1e-7 in the derivative's units, and its
truncation error vanishes where the active set does not change within the step (the loss is
then smooth, and these losses are nearly linear).  Measured agreement: 1e-8 to 1e-11
relative.  The tests ask for 1e-6 relative (plus 1e-8 absolute for derivatives that vanish):
a decade tighter than the issue's 1e-5 target, a decade and more above what was measured.

cvxpy's own derivative (``Problem.backward``) needs diffcp (the `gradients` and `test`
extras); its test is skipped where diffcp is not installed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest

from wuerfel_cvx import Scene, Square, simulate
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.formulations import Formulation
from wuerfel_cvx.gradients import GradientError
from wuerfel_cvx.lab.bench.report_gradients import perturbed
from wuerfel_cvx.scenes.library import FLOOR, launched_box_scene

pytestmark = pytest.mark.integration

G = 9.81
EPS = 1e-6
RELATIVE = 1e-6
ABSOLUTE = 1e-8
SOLVERS = ("CLARABEL", "OSQP", "PIQP")

Loss = Callable[[np.ndarray], np.ndarray]
"""The gradient of a linear loss with respect to the points (the loss is its dot product
with the points)."""


def final_mean_x(points: np.ndarray) -> np.ndarray:
    """Gradient of the first body's mean corner x at the last state."""
    gradient = np.zeros_like(points)
    gradient[-1, :4, 0] = 0.25
    return gradient


def final_heights(points: np.ndarray) -> np.ndarray:
    """Gradient of the sum of every corner's height at the last state."""
    gradient = np.zeros_like(points)
    gradient[-1, :, 1] = 1.0
    return gradient


def top_x(points: np.ndarray) -> np.ndarray:
    """Gradient of the top body's mean corner x at the last state, and at every state."""
    gradient = np.zeros_like(points)
    gradient[:, -4:, 0] = 0.25 / points.shape[0]
    gradient[-1, -4:, 0] += 0.25
    return gradient




def run(scene: Scene, steps: int, solver: str, gradients: bool = False,  # type: ignore[no-untyped-def]
        formulation: str | Formulation = "rigid"):
    """The run of ``scene`` at dt 1/240 (``rigid`` with ``ccp`` friction unless given)."""
    return simulate(scene, dt=1 / 240, steps=steps, solver=solver, formulation=formulation,
                    gradients=gradients)


def finite_difference(scene: Scene, loss: Loss, body: int, name: str, component: int,
                      steps: int, solver: str, formulation: str | Formulation = "rigid",
                      ) -> float:
    """Central difference of the linear loss ``loss`` with respect to one input."""
    values = []
    for sign in (1.0, -1.0):
        points = run(perturbed(scene, body, name, component, sign * EPS), steps, solver,
                     formulation=formulation).points
        values.append(float(np.sum(loss(points) * points)))
    return (values[0] - values[1]) / (2.0 * EPS)


def assert_matches_differences(scene: Scene, loss: Loss, inputs: list[tuple[int, str, int]],
                               steps: int, solver: str, formulation: str | Formulation = "rigid",
                               *, absolute: float = ABSOLUTE) -> dict[str, np.ndarray]:
    """Adjoint and central differences agree on every input ``(body, name, component)``."""
    trajectory = run(scene, steps, solver, gradients=True, formulation=formulation)
    names = tuple(dict.fromkeys(name for _, name, _ in inputs))
    gradient = trajectory.gradient(loss(trajectory.points), names)
    assert gradient["crossings"] == 0, gradient["flagged_steps"]
    if formulation == "rigid":  # ccp hovers off its sliding contacts; coulomb stays at 0
        assert gradient["gap_switch_steps"].size == 0, gradient["gap_switch_steps"]
    for body, name, component in inputs:
        value = gradient[name][body]
        adjoint = float(value[component] if np.ndim(value) else value)
        expected = finite_difference(scene, loss, body, name, component, steps, solver,
                                     formulation)
        assert adjoint == pytest.approx(expected, rel=RELATIVE, abs=absolute), (name,
                                                                                component)
    return gradient


def slide_scene() -> Scene:
    """The launched box of the friction targets, 1 mm above the table (off the rate switch)."""
    return perturbed(launched_box_scene(3.0, 0.5), 0, "center", 1, 1e-3)


ALL_INPUTS = [(0, "center", 0), (0, "center", 1), (0, "angle", 0), (0, "velocity", 0),
              (0, "velocity", 1), (0, "angular_velocity", 0), (0, "friction", 0),
              (0, "mass", 0)]


@pytest.mark.parametrize("solver", SOLVERS)
def test_slide_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(slide_scene(), final_mean_x, ALL_INPUTS, 40, solver)


def test_tilted_drop_gradient_matches_finite_differences() -> None:
    square = Square(center=(0.0, 0.9), angle=0.3, velocity=(0.4, -1.0), angular_velocity=1.0,
                    friction=0.4)
    scene = Scene(name="tilted-drop", squares=(square,), tables=(FLOOR,))
    floor_friction = dataclasses.replace(FLOOR, friction=0.4)
    scene = dataclasses.replace(scene, tables=(floor_friction,))
    assert_matches_differences(scene, final_heights, ALL_INPUTS, 60, "CLARABEL")


@pytest.mark.parametrize("solver", SOLVERS)
def test_resting_stack_gradient_matches_finite_differences(solver: str) -> None:
    """A 3-stack at rest with friction: every cone row tight, more tight rows than unknowns.

    Its contacts sit at the speculative/Baumgarte switch (distance 0), so only inputs that
    leave the gaps alone are differentiated (horizontal positions and velocities, masses,
    friction); the adjoint's dependent rows are the case of
    :mod:`wuerfel_cvx.gradients.adjoint`'s last paragraph.
    """
    squares = tuple(Square(center=(0.0, 0.5 + k), friction=0.6) for k in range(3))
    scene = Scene(name="stack-3-rough", squares=squares,
                  tables=(dataclasses.replace(FLOOR, friction=0.6),))
    inputs = [(2, "center", 0), (1, "center", 0), (2, "velocity", 0), (1, "velocity", 0),
              (2, "friction", 0), (1, "mass", 0), (2, "angular_velocity", 0)]
    trajectory = run(scene, 30, solver, gradients=True)
    names = tuple(dict.fromkeys(name for _, name, _ in inputs))
    gradient = trajectory.gradient(top_x(trajectory.points), names)
    assert gradient["crossings"] == 0
    for body, name, component in inputs:
        value = gradient[name][body]
        adjoint = float(value[component] if np.ndim(value) else value)
        expected = finite_difference(scene, top_x, body, name, component, 30, solver)
        assert adjoint == pytest.approx(expected, rel=RELATIVE, abs=ABSOLUTE), (name, body)


def test_slide_gradient_meets_the_analytic_stopping_distance() -> None:
    speed, mu = 3.0, 0.5
    trajectory = run(launched_box_scene(speed, mu), 200, "CLARABEL", gradients=True)
    gradient = trajectory.gradient(final_mean_x(trajectory.points), ("velocity", "friction"))
    # the contact's coefficient is sqrt(mu_box mu_table): on a table of the same mu, the
    # contact's derivative is twice the box's
    assert gradient["velocity"][0, 0] == pytest.approx(speed / (mu * G), rel=0.03)
    assert 2.0 * gradient["friction"][0] == pytest.approx(-speed**2 / (2 * mu**2 * G),
                                                          rel=0.03)


def test_gradient_without_recording_is_an_input_error() -> None:
    trajectory = run(slide_scene(), 3, "CLARABEL")
    with pytest.raises(InputError, match="without gradients"):
        trajectory.gradient(np.zeros_like(trajectory.points), "velocity")


def test_gradient_of_unsupported_run_is_refused_up_front() -> None:
    with pytest.raises(GradientError, match="rigid"):
        simulate(slide_scene(), dt=1 / 240, steps=1, formulation="seed", gradients=True)


def test_gradient_through_an_unverified_step_is_refused() -> None:
    trajectory = run(slide_scene(), 3, "CLARABEL", gradients=True)
    assert trajectory.tape is not None
    record = trajectory.tape.steps[1]
    trajectory.tape.steps[1] = dataclasses.replace(
        record, solution=dataclasses.replace(record.solution, verified=False))
    with pytest.raises(GradientError, match="not verified"):
        trajectory.gradient(np.zeros_like(trajectory.points), "velocity")


def test_gradient_checks_its_arguments() -> None:
    trajectory = run(slide_scene(), 2, "CLARABEL", gradients=True)
    with pytest.raises(GradientError, match="shape"):
        trajectory.gradient(np.zeros((1, 4, 2)), "velocity")
    with pytest.raises(GradientError, match="unknown"):
        trajectory.gradient(np.zeros_like(trajectory.points), "spin")


def test_step_adjoint_matches_cvxpy_derivative() -> None:
    """One step's adjoint against cvxpy's own derivative of the declared DPP problem.

    The slide's step QP (``min |sqrt(w) (x - t)|^2  s.t.  G x >= h``, ``t``, ``G`` and ``h``
    parameters) differentiated by ``Problem.backward`` (diffcp, an optional package: the
    test is skipped without it) against :func:`~wuerfel_cvx.gradients.adjoint.qp_adjoint`.
    diffcp differentiates the conic form solved by SCS to about 1e-6; 1e-4 relative allows
    it.
    """
    pytest.importorskip("diffcp")
    import cvxpy as cp

    from wuerfel_cvx.gradients.adjoint import qp_adjoint

    trajectory = run(slide_scene(), 12, "CLARABEL", gradients=True)
    assert trajectory.tape is not None
    record = next(record for record in reversed(trajectory.tape.steps)  # a contact step
                  if record.solution.active is not None and record.solution.active.size)
    qp, solution = record.qp, record.solution
    loss_gradient = np.array([1.0, 0.5, 2.0])
    adjoint = qp_adjoint(qp, solution.x, solution.ineq_dual, solution.active, loss_gradient, 1)

    x = cp.Variable(qp.n_variables)
    target = cp.Parameter(qp.n_variables, value=qp.target)
    rows = cp.Parameter(qp.ineq_matrix.shape, value=qp.ineq_matrix.toarray())
    rhs = cp.Parameter(qp.n_inequalities, value=qp.ineq_rhs)
    root = np.sqrt(qp.weights)
    problem = cp.Problem(cp.Minimize(cp.sum_squares(cp.multiply(root, x) - cp.multiply(root,
                                                                                        target))),
                         [rows @ x >= rhs])
    assert problem.is_dpp()
    problem.solve(solver=cp.SCS, requires_grad=True, eps=1e-12, max_iters=100_000)
    x.gradient = loss_gradient
    problem.backward()
    dense_rows = np.zeros(qp.ineq_matrix.shape)
    dense_rhs = np.zeros(qp.n_inequalities)
    dense_rows[adjoint.rows] = (adjoint.row_multiplier[:, None] * adjoint.unknowns_adjoint
                                - adjoint.row_adjoint[:, None] * solution.x)
    dense_rhs[adjoint.rows] = adjoint.row_adjoint
    scale = float(np.max(np.abs(adjoint.target)))
    np.testing.assert_allclose(target.gradient, adjoint.target, atol=1e-4 * scale)
    np.testing.assert_allclose(rhs.gradient, dense_rhs, atol=1e-4 * scale)
    np.testing.assert_allclose(rows.gradient, dense_rows, atol=1e-4 * scale)


def test_gravity_gradient_matches_finite_differences() -> None:
    scene = slide_scene()
    trajectory = run(scene, 30, "CLARABEL", gradients=True)
    adjoint = trajectory.gradient(final_heights(trajectory.points), "gravity")["gravity"]
    for axis in range(2):
        values = []
        for sign in (1.0, -1.0):
            gravity = list(scene.gravity)
            gravity[axis] += sign * EPS
            points = run(dataclasses.replace(scene, gravity=tuple(gravity)), 30,
                         "CLARABEL").points
            values.append(float(np.sum(final_heights(points) * points)))
        expected = (values[0] - values[1]) / (2.0 * EPS)
        assert adjoint[axis] == pytest.approx(expected, rel=RELATIVE, abs=ABSOLUTE)
