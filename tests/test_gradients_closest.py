"""Gradients through rigid's closest-approach rows (issue 26, the main formulations).

``RigidFormulation(linearisation="closest-approach")`` poses two rows per contact, linearised
along the rigid motion of a linearisation point ``about`` at the contact's closest-approach
time ``tau*``, in Gauss-Newton passes.  The backward pass differentiates each pass's rows
with respect to the start coordinates, the friction coefficients and ``about``, through
``tau*`` as the forward pass computes it (:func:`wuerfel_cvx.gradients.rigid.approach_rows`),
and chains through the passes (:mod:`wuerfel_cvx.gradients.backward`).  Checked here:

* the rows' derivatives against central differences of the formulation's own row builder
  (:func:`~wuerfel_cvx.formulations.velocity.closest_approach` and
  :func:`~wuerfel_cvx.formulations.velocity.rows_along`), on spinning contacts where
  ``tau*`` is interior and moves with the inputs;
* whole runs against central differences: the three smooth segments of
  :mod:`test_gradients` (one pass a step there), with ``ccp`` for CLARABEL, OSQP and PIQP and
  with ``coulomb``; and rain-4 with spins at dt 0.01, whose landings take two passes.

Tolerances as in :mod:`test_gradients` (1e-6 relative, 1e-8 absolute; measured 1e-8 to
1e-11, and the rows' derivatives 1e-8 against differences of step 1e-7, whose round-off
is 1e-16 / 1e-7 = 1e-9 relative to rows of order 1 to 1e3).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from test_gradients import (
    ALL_INPUTS,
    SOLVERS,
    assert_matches_differences,
    final_heights,
    final_mean_x,
    slide_scene,
    top_x,
)
from wuerfel_cvx import Scene, Square, simulate
from wuerfel_cvx.formulations import motion
from wuerfel_cvx.formulations.rigid import RigidFormulation
from wuerfel_cvx.formulations.velocity import closest_approach, rows_along
from wuerfel_cvx.gradients import GradientError
from wuerfel_cvx.gradients.rigid import APPROACH_LOCAL, approach_rows
from wuerfel_cvx.scenes.library import FLOOR

pytestmark = pytest.mark.integration

CLOSEST = RigidFormulation(linearisation="closest-approach")
CLOSEST_COULOMB = RigidFormulation(linearisation="closest-approach", friction_model="coulomb",
                                   coulomb_tolerance=1e-10)


def tilted_drop() -> Scene:
    """A square landing on a corner with spin and friction (as in :mod:`test_gradients`)."""
    square = Square(center=(0.0, 0.9), angle=0.3, velocity=(0.4, -1.0), angular_velocity=1.0,
                    friction=0.4)
    return Scene(name="tilted-drop", squares=(square,),
                 tables=(dataclasses.replace(FLOOR, friction=0.4),))


def resting_stack() -> Scene:
    return Scene(name="stack-3-rough",
                 squares=tuple(Square(center=(0.0, 0.5 + k), friction=0.6) for k in range(3)),
                 tables=(dataclasses.replace(FLOOR, friction=0.6),))


def spinning_rain() -> Scene:
    """rain-4 with each square spinning: their landings at dt 0.01 take two passes."""
    scene = Scene.named("rain-4")
    spins = (1.5, -2.0, 1.0, -1.0)
    return dataclasses.replace(scene, squares=tuple(
        dataclasses.replace(square, angular_velocity=spin)
        for square, spin in zip(scene.squares, spins, strict=True)))


STACK_INPUTS = [(2, "center", 0), (1, "center", 0), (2, "velocity", 0), (1, "velocity", 0),
                (2, "friction", 0), (1, "mass", 0), (2, "angular_velocity", 0)]


@pytest.mark.parametrize("solver", SOLVERS)
def test_closest_approach_drop_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(tilted_drop(), final_heights, ALL_INPUTS, 60, solver, CLOSEST)


@pytest.mark.parametrize("solver", SOLVERS)
def test_closest_approach_slide_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(slide_scene(), final_mean_x, ALL_INPUTS, 40, solver, CLOSEST)


@pytest.mark.parametrize("solver", SOLVERS)
def test_closest_approach_stack_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(resting_stack(), top_x, STACK_INPUTS, 30, solver, CLOSEST)


@pytest.mark.parametrize("scene, loss, steps", [(tilted_drop(), final_heights, 60),
                                                (slide_scene(), final_mean_x, 40)])
def test_closest_approach_coulomb_gradient_matches_finite_differences(
        scene: Scene, loss: object, steps: int) -> None:
    assert_matches_differences(scene, loss, ALL_INPUTS, steps, "CLARABEL",  # type: ignore[arg-type]
                               CLOSEST_COULOMB)


def final_state(points: np.ndarray) -> np.ndarray:
    """Gradient of every corner's height plus 0.3 times its x, at the last state."""
    gradient = np.zeros_like(points)
    gradient[-1, :, 1] = 1.0
    gradient[-1, :, 0] = 0.3
    return gradient


def test_gradient_chains_through_the_gauss_newton_passes() -> None:
    """Two-pass landings: pass 2's rows are linearised about pass 1's answer."""
    assert_chained_passes_match_differences(
        CLOSEST, [(body, name, component) for body in (0, 3)
                  for name, component in (("center", 1), ("angle", 0), ("velocity", 1),
                                          ("angular_velocity", 0), ("mass", 0))])


def assert_chained_passes_match_differences(formulation: object,
                                            inputs: list[tuple[int, str, int]]) -> None:
    """Spinning rain-4's gradient through ``formulation`` against central differences.

    64 steps, some taking two passes; the loss is :func:`final_state`'s, each input a
    ``(body, name, component)``, the difference step 1e-6 over the whole run.
    """
    scene, steps = spinning_rain(), 64
    trajectory = simulate(scene, dt=0.01, steps=steps, solver="CLARABEL",
                          formulation=formulation, gradients=True)  # type: ignore[arg-type]
    assert trajectory.tape is not None
    assert any(record.passes for record in trajectory.tape.steps)
    gradient = trajectory.gradient(final_state(trajectory.points),
                                   tuple(dict.fromkeys(name for _, name, _ in inputs)))
    for body, name, component in inputs:
        value = gradient[name][body]
        adjoint = float(value[component] if np.ndim(value) else value)
        values = []
        for sign in (1.0, -1.0):
            changed = dataclasses.replace(scene, squares=tuple(
                _moved(square, name, component, sign * 1e-6) if index == body else square
                for index, square in enumerate(scene.squares)))
            points = simulate(changed, dt=0.01, steps=steps, solver="CLARABEL",
                              formulation=formulation).points  # type: ignore[arg-type]
            values.append(float(np.sum(final_state(points) * points)))
        expected = (values[0] - values[1]) / 2e-6
        assert adjoint == pytest.approx(expected, rel=1e-6, abs=1e-8), (name, body)


def _moved(square: Square, name: str, component: int, step: float) -> Square:
    value = getattr(square, name)
    if isinstance(value, tuple):
        changed = list(value)
        changed[component] += step
        return dataclasses.replace(square, **{name: tuple(changed)})
    return dataclasses.replace(square, **{name: value + step})


def test_closest_approach_rows_derivatives_match_the_row_builder() -> None:
    """:func:`approach_rows` against differences of velocity's own rows, ``about`` moved.

    The tilted drop's landing steps: the square spins, so ``tau*`` is interior (refined by
    its parabola) and moves with ``about``; the row builder's right sides move with it.
    """
    trajectory = simulate(tilted_drop(), dt=1 / 240, steps=60, solver="CLARABEL",
                          formulation=CLOSEST, gradients=True)
    assert trajectory.tape is not None
    model, dt, step = trajectory.tape.model, 1 / 240, 1e-7
    checked = 0
    for record in trajectory.tape.steps:
        qp, points = record.qp, trajectory.points[record.step - 1]
        if not len(qp.contacts):
            continue
        rows = approach_rows(model, points, qp.contacts, qp, CLOSEST.push_speed, dt)
        about = qp.linearised_about
        assert about is not None
        for axis in range(3):  # the point body is the square (the floor's edge)
            moved = np.zeros_like(about)
            moved[axis] = step
            differences = (_normal_rhs(model, points, qp.contacts, about + moved, dt)
                           - _normal_rhs(model, points, qp.contacts, about - moved, dt)
                           ) / (2 * step)
            column = APPROACH_LOCAL.index(("point_ux", "point_uy", "point_omega")[axis])
            normal = rows.rhs.grad[:len(differences), column]
            np.testing.assert_allclose(normal, differences, rtol=1e-6, atol=1e-6)
        checked += 1
    assert checked > 0


def _normal_rhs(model, points, contacts, about, dt):  # type: ignore[no-untyped-def]
    corners = motion.corner_velocities(points, about.reshape(-1, 3)).ravel()
    approach = closest_approach(model, points, contacts, corners, dt, CLOSEST.push_speed)
    return rows_along(model, contacts, approach).rhs


def test_coulomb_step_that_relinearised_is_refused() -> None:
    """A Coulomb fixed point whose contact QPs were re-linearised is not chained."""
    trajectory = simulate(tilted_drop(), dt=1 / 240, steps=60, solver="CLARABEL",
                          formulation=CLOSEST_COULOMB, gradients=True)
    assert trajectory.tape is not None
    index = next(k for k, record in enumerate(trajectory.tape.steps) if record.forces is not None)
    record = trajectory.tape.steps[index]
    assert record.qp.linearised_about is not None
    shifted = dataclasses.replace(record.qp, linearised_about=record.qp.linearised_about + 0.1)
    trajectory.tape.steps[index] = dataclasses.replace(record, qp=shifted)
    with pytest.raises(GradientError, match="linearised about"):
        trajectory.gradient(np.zeros_like(trajectory.points), "velocity")


def _spinning_corner() -> tuple[np.ndarray, object, object]:
    """A corner of a square spinning at -200 rad/s past a table's top edge (``y = 0``).

    The corner starts 0.1 rad above its centre's level and turns below it within the step,
    so the gap turns from concave to convex: the mean rate ``psi / tau`` has an interior
    minimum, and ``tau*`` is a parabola's vertex that moves with the inputs.
    """
    from wuerfel_cvx.formulations.motion import BodyMotion
    from wuerfel_cvx.gradients.rigid import _ApproachInputs
    from wuerfel_cvx.step.contacts import Contacts

    box = np.array([[0.5, 0.0], [0.0, 0.5], [-0.5, 0.0], [0.0, -0.5]])
    table = np.array([[1.0, 0.0], [-1.0, 0.0], [-1.0, -1.0], [1.0, -1.0]])
    x = np.zeros(14)
    x[3:6] = (0.0, 0.1, 0.1)  # the square's centre and angle
    x[11:14] = (0.0, 2.0, -200.0)  # its linearisation point's velocity and spin
    contacts = Contacts(point=np.array([0]), edge_i=np.array([5]), edge_j=np.array([4]),
                        point_body=np.array([0]), edge_body=np.array([1]),
                        distance=np.array([0.1]))

    def motion(values: np.ndarray) -> BodyMotion:
        return BodyMotion(center=np.array([values[3:5], [0.0, 0.0]]),
                          angle=np.array([values[5], 0.0]),
                          velocity=np.array([values[11:13], [0.0, 0.0]]),
                          spin=np.array([values[13], 0.0]),
                          reference=np.stack([box, table]), n_boxes=1,
                          fitted=np.stack([box @ _rotation(values[5]).T, table]))

    inputs = _ApproachInputs(table[[1]], table[[0]], box[[0]], np.array([False]), 1 / 240, 1.0)
    return x, (motion, contacts), inputs


def test_closest_approach_time_is_differentiated_where_it_moves() -> None:
    """``tau*`` at a parabola's vertex: its and ``psi``'s derivatives against differences.

    Differences of the formulation's own
    :func:`~wuerfel_cvx.formulations.velocity.approach_along`.  Also the envelope
    theorem, checked rather than assumed: ``psi / tau`` at ``tau*`` has the same derivative
    with ``tau*`` held, ``psi`` alone (and with it the row's right side ``G v0 - psi / tau*``
    and its matrix ``G(tau*)``) does not.
    """
    from wuerfel_cvx.formulations.velocity import approach_along
    from wuerfel_cvx.gradients.rigid import COMPLEX_STEP, _closest, _Held

    x, (motion, contacts), inputs = _spinning_corner()
    dt, step = 1 / 240, 1e-7

    def forward(values: np.ndarray) -> tuple[float, float]:
        approach = approach_along(motion(values), contacts, np.zeros(0), dt, 1.0)
        tau, psi = approach.closest, approach.margin
        return float(tau[0]), float(psi[0])

    tau, psi, _, _, choices = _closest(x[None, :].astype(complex), inputs, None, False)
    assert choices["take"][0] and not choices["flat"][0]
    assert forward(x) == pytest.approx((tau[0].real, psi[0].real), rel=1e-12)
    held = _Held(at_rate=np.array([False]), **choices)
    for column in (4, 5, 12, 13):  # the square's y, angle, and about's v_y, omega
        stepped = x[None, :].astype(complex)
        stepped[0, column] += 1j * COMPLEX_STEP
        tau_d, psi_d, _, _, _ = _closest(stepped, inputs, held, False)
        tau_h, psi_h, _, _, _ = _closest(stepped, inputs, held, True)
        plus, minus = x.copy(), x.copy()
        plus[column] += step
        minus[column] -= step
        (tau_p, psi_p), (tau_m, psi_m) = forward(plus), forward(minus)
        d_tau, d_psi = tau_d[0].imag / COMPLEX_STEP, psi_d[0].imag / COMPLEX_STEP
        # the differences' round-off: the vertex's noise (1e-16 s over the step 1e-7, times
        # the parabola's amplification: measured 5e-10) times psi' (60 m/s): 3e-8
        assert d_tau == pytest.approx((tau_p - tau_m) / (2 * step), rel=1e-5, abs=1e-9)
        assert d_psi == pytest.approx((psi_p - psi_m) / (2 * step), rel=1e-5, abs=1e-7)
        t, p = tau[0].real, psi[0].real
        mean_rate = (d_psi * t - p * d_tau) / t**2
        # the vertex is the minimiser up to the parabola's error: measured 3e-6 relative
        assert mean_rate == pytest.approx(psi_h[0].imag / COMPLEX_STEP / t, rel=1e-4, abs=1e-6)
    # held, psi's derivative with respect to the angle is another number
    stepped = x[None, :].astype(complex)
    stepped[0, 5] += 1j * COMPLEX_STEP
    moving, fixed = (_closest(stepped, inputs, held, hold)[1][0].imag for hold in (False, True))
    assert abs(moving - fixed) > 0.1 * abs(moving)


def _rotation(angle: float) -> np.ndarray:
    """The rotation matrix of ``angle`` (rad)."""
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
