"""Gradients through the ``velocity`` formulations (issue 26, the main formulations).

``velocity`` poses its step in corner velocities held by rods, and the backward pass
differentiates that corner-space QP and its advance (:mod:`wuerfel_cvx.gradients.velocity`).
Checked here, independently of each other:

* whole runs against central finite differences: the smooth segments of
  :mod:`test_gradients` (a tilted drop, a slide with ``ccp``, a resting stack) with
  closest-approach rows for CLARABEL, OSQP and PIQP, with start rows
  (``velocity-baumgarte``), with ``coulomb`` friction (its fixed point at
  ``coulomb_tolerance`` 1e-10, as in :mod:`test_gradients_closest`), and spinning rain-4
  (frictionless, a step of two passes);
* against ``rigid``'s gradient of the same run: on these scenes the two formulations pose
  the same QP in different unknowns (their trajectories agree to 1e-14 m), so the exact
  derivatives agree too, though one comes from an 8-unknown KKT system with rods per body and
  the other from a 3-unknown one;
* the fit's two maps are each other's transposes, and what is not covered is refused.

Tolerances: the finite differences as in :mod:`test_gradients` (1e-6 relative, 1e-8
absolute; measured 1e-8 to 1e-11).  Against ``rigid``: 1e-9 relative plus 1e-11 absolute;
the two adjoints are the same derivative computed by different linear algebra, each step's
solve refined to round-off (measured 1e-14 absolute on derivatives of order 1), so the
tolerance is five decades above that and far below any modelling difference.
"""

from __future__ import annotations

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
from test_gradients_closest import (
    STACK_INPUTS,
    assert_chained_passes_match_differences,
    final_state,
    resting_stack,
    spinning_rain,
    tilted_drop,
)
from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.formulations import Formulation
from wuerfel_cvx.formulations.rigid import RigidFormulation
from wuerfel_cvx.formulations.velocity import VelocityFormulation
from wuerfel_cvx.gradients import WRT_NAMES, GradientError
from wuerfel_cvx.gradients.velocity import CornerFit
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.integration

AGAINST_RIGID = {"rel": 1e-9, "abs": 1e-11}
"""Velocity's gradient against rigid's of the same run (the module docstring)."""

WATCHED = {"drop": (tilted_drop, final_heights, 60), "slide": (slide_scene, final_mean_x, 40),
           "stack": (resting_stack, top_x, 30)}


@pytest.mark.parametrize("solver", SOLVERS)
def test_velocity_drop_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(tilted_drop(), final_heights, ALL_INPUTS, 60, solver,
                               "velocity")


@pytest.mark.parametrize("solver", SOLVERS)
def test_velocity_slide_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(slide_scene(), final_mean_x, ALL_INPUTS, 40, solver, "velocity")


@pytest.mark.parametrize("solver", SOLVERS)
def test_velocity_stack_gradient_matches_finite_differences(solver: str) -> None:
    assert_matches_differences(resting_stack(), top_x, STACK_INPUTS, 30, solver, "velocity")


@pytest.mark.parametrize("linearisation", ["closest-approach", "start"])
@pytest.mark.parametrize("case", ["drop", "slide"])
def test_velocity_coulomb_gradient_matches_finite_differences(case: str,
                                                              linearisation: str) -> None:
    scene, loss, steps = WATCHED[case]
    formulation = VelocityFormulation(friction_model="coulomb", coulomb_tolerance=1e-10,
                                      linearisation=linearisation)  # type: ignore[arg-type]
    assert_matches_differences(scene(), loss, ALL_INPUTS, steps, "CLARABEL", formulation)


@pytest.mark.parametrize("case", ["drop", "slide"])
def test_velocity_baumgarte_gradient_matches_finite_differences(case: str) -> None:
    scene, loss, steps = WATCHED[case]
    assert_matches_differences(scene(), loss, ALL_INPUTS, steps, "CLARABEL",
                               "velocity-baumgarte")


def _gradients(scene: Scene, loss: object, steps: int, formulation: str | Formulation,
               dt: float) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    trajectory = simulate(scene, dt=dt, steps=steps, solver="CLARABEL",
                          formulation=formulation, gradients=True)
    return trajectory.points, trajectory.gradient(loss(trajectory.points),  # type: ignore[operator]
                                                  WRT_NAMES)


PAIRS = {"velocity": ("velocity", "rigid"),
         "velocity-baumgarte": ("velocity-baumgarte", "rigid-baumgarte"),
         "velocity-coulomb": (VelocityFormulation(friction_model="coulomb",
                                                  coulomb_tolerance=1e-10),
                              RigidFormulation(friction_model="coulomb",
                                               coulomb_tolerance=1e-10))}
"""Each velocity formulation and the rigid one posing its QP in body velocities."""


@pytest.mark.parametrize("pair", PAIRS)
@pytest.mark.parametrize("case", [*WATCHED, "rain"])
def test_velocity_gradient_matches_rigid_gradient_of_the_same_run(case: str,
                                                                  pair: str) -> None:
    scene, loss, steps, dt = ((spinning_rain, final_state, 64, 0.01) if case == "rain"
                              else (*WATCHED[case], 1 / 240))
    formulation, rigid = PAIRS[pair]
    points, gradient = _gradients(scene(), loss, steps, formulation, dt)
    rigid_points, expected = _gradients(scene(), loss, steps, rigid, dt)
    assert np.max(np.abs(points - rigid_points)) < 1e-12  # the same run
    for name in WRT_NAMES:
        np.testing.assert_allclose(gradient[name], expected[name], rtol=AGAINST_RIGID["rel"],
                                   atol=AGAINST_RIGID["abs"], err_msg=name)
    assert gradient["crossings"] == expected["crossings"]


def test_velocity_gradient_with_the_sixth_rod_matches_rigid_gradient() -> None:
    """``extra_rod``: six rods a box, one of them dependent (the KKT solve is rank deficient)."""
    gradients = []
    for formulation, options in (("velocity", {"extra_rod": True}), ("rigid", {})):
        trajectory = simulate(tilted_drop(), dt=1 / 240, steps=60, solver="CLARABEL",
                              formulation=formulation, gradients=True, **options)
        gradients.append(trajectory.gradient(final_heights(trajectory.points), WRT_NAMES))
    for name in WRT_NAMES:
        np.testing.assert_allclose(gradients[0][name], gradients[1][name],
                                   rtol=AGAINST_RIGID["rel"], atol=AGAINST_RIGID["abs"],
                                   err_msg=name)


def test_velocity_gradient_chains_through_the_gauss_newton_passes() -> None:
    """Frictionless spinning rain: a landing whose step takes two passes."""
    assert_chained_passes_match_differences(
        "velocity", [(0, "center", 1), (0, "angle", 0), (3, "angular_velocity", 0),
                     (3, "mass", 0)])


@pytest.mark.unit
def test_the_fit_and_its_transpose_are_adjoint() -> None:
    """``a . J w = J' a . w``, and ``J`` of a rigid motion's corner velocities is the motion."""
    scene = tilted_drop()
    model = Model.from_scene(scene)
    points = scene.initial_points()
    fit = CornerFit.of(model, points)
    rng = np.random.default_rng(1)
    corner, body = rng.normal(size=8 * model.n_boxes), rng.normal(size=3 * model.n_boxes)
    assert body @ fit.to_bodies(corner) == pytest.approx(fit.to_corners(body) @ corner,
                                                         rel=1e-13)
    rigid = scene.initial_velocities().ravel()
    square = scene.squares[0]
    np.testing.assert_allclose(fit.to_bodies(rigid), [*square.velocity,
                                                      square.angular_velocity], atol=1e-14)


@pytest.mark.unit
@pytest.mark.parametrize("options, message", [
    ({"formulation": VelocityFormulation(position_update="linear")}, "rigid position update"),
    ({"formulation": "velocity", "table_mass": 10.0}, "fixed tables"),
])
def test_velocity_gradients_refuse_what_they_do_not_cover(options: dict[str, object],
                                                          message: str) -> None:
    with pytest.raises(GradientError, match=message):
        simulate(slide_scene(), dt=1 / 240, steps=1, gradients=True, **options)  # type: ignore[arg-type]
