"""Light bodies: their QPs are solved in units where the weights are not small.

A scene whose masses are all ``4^-k`` times another's has, in the velocity formulation, the
same trajectory (the minimiser of ``sum m |v - v_free|^2`` does not depend on the masses'
common scale).  The solvers' tolerances are partly absolute, so a QP of light bodies was
solved less accurately than its heavy twin; with the weights scaled up by a power of four
(:func:`wuerfel_cvx.solve.scaling.weights_scale`) the light QP the solver sees is the heavy one,
bit for bit, and so is the trajectory.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from qp_bank import qp_bank
from wuerfel_cvx import simulate
from wuerfel_cvx.scenes.library import named_scene
from wuerfel_cvx.scenes.scene import Scene
from wuerfel_cvx.solve.scaling import WEIGHT_FLOOR, scaled_qp, weights_scale

pytestmark = pytest.mark.integration

SOLVERS = ("CLARABEL", "OSQP", "PIQP")
FORMULATION = "velocity"
"""The runs compared bit for bit: the velocity formulation, whose weights are the corner
masses (0.25 kg for the library's unit squares, within a factor four above the floor, so
the light QP is scaled back to the heavy one exactly).  The rigid formulation's weights
(mass and moment of inertia) are not in one such band, so its light and heavy QPs are
seen in units a power of four apart and agree to round-off, not bit for bit."""


def lighter(scene: Scene, factor: float) -> Scene:
    """``scene`` with every body's mass times ``factor``."""
    return dataclasses.replace(
        scene, squares=tuple(dataclasses.replace(s, mass=s.mass * factor) for s in scene.squares),
        boxes=tuple(dataclasses.replace(b, mass=b.mass * factor) for b in scene.boxes))


@pytest.mark.unit
@pytest.mark.parametrize("largest", [1.0, 0.25, 0.3, 0.2, 0.0625, 0.06, 2e-4, 1e-9, 3.0])
def test_weights_scale_is_the_smallest_power_of_four_reaching_the_floor(largest: float) -> None:
    bank_qp = qp_bank()[0].build()
    weights = np.linspace(largest / 7.0, largest, bank_qp.n_variables)
    qp = dataclasses.replace(bank_qp, weights=weights)
    scale = weights_scale(qp)
    expected = 1.0 if largest >= WEIGHT_FLOOR else 4.0 ** math.ceil(
        math.log(WEIGHT_FLOOR / largest, 4.0) - 1e-12)
    assert scale == expected
    assert math.log(scale, 4.0) == round(math.log(scale, 4.0))  # a power of four
    seen = scaled_qp(qp, 1.0, scale)
    assert seen.weights.max() >= min(largest, WEIGHT_FLOOR)
    if scale > 1.0:
        assert seen.weights.max() / 4.0 < WEIGHT_FLOOR


@pytest.mark.parametrize("solver", SOLVERS)
def test_a_stack_lighter_by_a_power_of_four_moves_bit_for_bit_as_the_heavy_one(
        solver: str) -> None:
    heavy = named_scene("stack-3")  # 1 kg squares: corner weights 0.25, solved as they are
    light = lighter(heavy, 4.0 ** -6)
    a = simulate(heavy, dt=0.01, steps=60, solver=solver, formulation=FORMULATION)
    b = simulate(light, dt=0.01, steps=60, solver=solver, formulation=FORMULATION)
    np.testing.assert_array_equal(a.points, b.points)


@pytest.mark.parametrize("friction_model", ["ccp", "coulomb"])
def test_friction_of_light_bodies_is_solved_as_that_of_heavy_ones(friction_model: str) -> None:
    heavy = named_scene("friction-slope")
    assert min(b.mass for b in (*heavy.squares, *heavy.boxes)) >= 4 * WEIGHT_FLOOR
    light = lighter(heavy, 4.0 ** -6)
    a = simulate(heavy, dt=1 / 60, steps=40, solver="CLARABEL", friction_model=friction_model,
                 formulation=FORMULATION)
    b = simulate(light, dt=1 / 60, steps=40, solver="CLARABEL", friction_model=friction_model,
                 formulation=FORMULATION)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.metrics["coulomb_iterations"].to_numpy(),
                                  b.metrics["coulomb_iterations"].to_numpy())


@pytest.mark.parametrize("friction_model", ["ccp", "coulomb"])
def test_light_bodies_in_rigid_coordinates_move_as_heavy_ones_to_round_off(
        friction_model: str) -> None:
    """The default (rigid) formulation: light and heavy runs agree to round-off.

    Their QPs are seen in units a power of four apart; both answers are polished to
    round-off, so the runs agree to 1e-12 m over 40 steps.
    """
    heavy = named_scene("friction-slope")
    light = lighter(heavy, 4.0 ** -6)
    a = simulate(heavy, dt=1 / 60, steps=40, friction_model=friction_model)
    b = simulate(light, dt=1 / 60, steps=40, friction_model=friction_model)
    assert a.info["formulation"] == "rigid"
    assert a.metrics["verified"].all() and b.metrics["verified"].all()
    np.testing.assert_allclose(a.points, b.points, rtol=0.0, atol=1e-12)
