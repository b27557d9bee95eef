"""Gradients through ``coulomb`` friction's fixed point (issue 26): differences and physics.

:mod:`wuerfel_cvx.gradients.adjoint` differentiates the fixed point's conditions (the
implicit function theorem on the fixed point, friction a function of the normal impulses),
not the last contact QP with its friction held.  Checked here against central differences
of whole runs, as the ``ccp`` gradients are in ``test_gradients``, on a slide (with the
friction's torque shifting the normal load between the two corners, so the fixed point
takes several iterations), a ramp slide, a tilted drop and a resting stack; and against the
analytic stopping distance.

Tolerances.  A run's state is the fixed point only to the fixed point's tolerance
(``coulomb_tolerance``, relative on the normal impulses); the differences here are of runs
with a tolerance of 1e-10, so that the fixed point's own error, divided by the difference's
step of 1e-6, stays below 1e-4 relative in the worst case and, the iteration converging
geometrically, is in practice at round-off (measured agreement 1e-9 to 1e-11).  The tests
ask for :data:`test_gradients.RELATIVE` (1e-6), as for ``ccp``.  The resting stack is the
exception, see its test.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from test_gradients import (
    ALL_INPUTS,
    SOLVERS,
    G,
    assert_matches_differences,
    final_heights,
    final_mean_x,
    perturbed,
    run,
    slide_scene,
    top_x,
)
from wuerfel_cvx import Scene, Square
from wuerfel_cvx.formulations import Formulation, get_formulation
from wuerfel_cvx.scenes.library import FLOOR, launched_box_scene, ramp_slide_scene

pytestmark = pytest.mark.integration

COULOMB: Formulation = dataclasses.replace(get_formulation("rigid"),  # type: ignore[type-var]
                                           friction_model="coulomb", coulomb_tolerance=1e-10)
"""``rigid`` with ``coulomb`` friction, its fixed point converged to 1e-10 (the module
docstring)."""


@pytest.mark.parametrize("solver", SOLVERS)
def test_coulomb_slide_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(slide_scene(), final_mean_x, ALL_INPUTS, 40, solver, COULOMB)


def down_slope(points: np.ndarray) -> np.ndarray:
    """Gradient of the square's mean corner position along the ramp, at the last state."""
    gradient = np.zeros_like(points)
    gradient[-1, :4] = 0.25 * np.array([np.cos(0.3), -np.sin(0.3)])
    return gradient


@pytest.mark.parametrize("linearisation", ["start", "closest-approach"])
def test_coulomb_ramp_slide_gradient_matches_finite_differences(linearisation: str) -> None:
    """A slide down a ramp, flat on it, with both of ``rigid``'s linearisations.

    Tilted off the ramp by the difference's step (1e-6 rad), a contact's rate row and its
    closest-approach row differ by about that much and both bind: four nearly dependent rows
    on three unknowns, whose multipliers' split is the solver's, so a contact's normal impulse
    is determined only to about 1e-9 relative. The fixed point cannot then settle to 1e-10
    (measured: 50 iterations at step 9, the normal impulses jittering by 1e-10 to 3e-9
    relative) and the difference measures that jitter (6e-7 against an adjoint of 0), so with
    the closest-approach rows the angle is left out; with the start rows it is checked.
    """
    scene = perturbed(ramp_slide_scene(0.2, 0.3), 0, "velocity", 0, 0.5)
    inputs = [key for key in ALL_INPUTS
              if linearisation == "start" or key[1] != "angle"]
    formulation = dataclasses.replace(COULOMB, linearisation=linearisation)
    assert_matches_differences(scene, down_slope, inputs, 40, "CLARABEL", formulation)


def test_coulomb_tilted_drop_gradient_matches_finite_differences() -> None:
    square = Square(center=(0.0, 0.9), angle=0.3, velocity=(0.4, -1.0), angular_velocity=1.0,
                    friction=0.4)
    scene = Scene(name="tilted-drop", squares=(square,),
                  tables=(dataclasses.replace(FLOOR, friction=0.4),))
    assert_matches_differences(scene, final_heights, ALL_INPUTS, 60, "CLARABEL", COULOMB)


def test_coulomb_resting_stack_gradient_matches_finite_differences() -> None:
    """A rough 3-stack at rest: every contact sticks, the no-slip rows dependent.

    A velocity pushed into the stick is stopped in the first step (the derivative is 0).
    The perturbed runs' contacts rest face to face on dependent rows, whose multipliers'
    split (and with it the fixed point's normal impulses) is the solver's: their final
    positions differ by about 2e-13 m where the stack does not move (measured: a difference
    of 1e-7 against an adjoint of 2e-18), so the velocities are compared to 1e-6 absolute.
    """
    squares = tuple(Square(center=(0.0, 0.5 + k), friction=0.6) for k in range(3))
    scene = Scene(name="stack-3-rough", squares=squares,
                  tables=(dataclasses.replace(FLOOR, friction=0.6),))
    assert_matches_differences(scene, top_x, [(2, "center", 0), (1, "center", 0),
                                              (2, "friction", 0), (1, "mass", 0),
                                              (2, "angular_velocity", 0)], 30, "CLARABEL",
                               COULOMB)
    assert_matches_differences(scene, top_x, [(2, "velocity", 0), (1, "velocity", 0)], 30,
                               "CLARABEL", COULOMB, absolute=1e-6)


@pytest.mark.parametrize(("model", "relative"), [("coulomb", 0.01), ("ccp", 0.03)])
def test_slide_gradient_meets_the_analytic_stopping_distance(model: str,
                                                             relative: float) -> None:
    """``dd/dv0 = v0 / (mu g)`` and ``dd/dmu = -v0^2 / (2 mu^2 g)`` at dt 1/240 (issue 26).

    The run's default fixed-point tolerance (1e-4).  The discrete slide stops after
    ``floor(v0 / (mu g dt))`` steps, which makes the discrete derivatives differ from the
    continuous ones by about ``mu g dt / v0`` (0.7 %) at most: the issue's 1 % and 3 %.
    """
    speed, mu = 3.0, 0.5
    formulation = dataclasses.replace(get_formulation("rigid"),  # type: ignore[type-var]
                                      friction_model=model)
    trajectory = run(launched_box_scene(speed, mu), 200, "CLARABEL", gradients=True,
                     formulation=formulation)
    gradient = trajectory.gradient(final_mean_x(trajectory.points), ("velocity", "friction"))
    assert gradient["crossings"] == 0
    assert gradient["velocity"][0, 0] == pytest.approx(speed / (mu * G), rel=relative)
    # the contact's coefficient is sqrt(mu_box mu_table): twice the box's derivative
    assert 2.0 * gradient["friction"][0] == pytest.approx(-speed**2 / (2 * mu**2 * G),
                                                          rel=relative)

