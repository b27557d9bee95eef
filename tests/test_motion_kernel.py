"""The compiled rigid update (numba) equals the NumPy rigid update bit for bit.

:func:`wuerfel_cvx.formulations.motion.rigid_step` and the rigid formulation's corner
velocities run their NumPy paths with ``_numba.enabled`` false (the reference) and the
kernels of :mod:`wuerfel_cvx.motion_kernel` with it true (and so the rigid formulation's
objective and the contact reach); both must give the same bits, on
library states (resting stacks: zero and negative-zero velocities), on random boxes of
every size and angle, and on a rigid run's whole trajectory.
"""

from __future__ import annotations

import numpy as np
import pytest

from kernel_paths import both
from test_contacts_fast import LIBRARY, library_states
from wuerfel_cvx import motion_kernel, simulate
from wuerfel_cvx.formulations.motion import rigid_step
from wuerfel_cvx.formulations.rigid import RigidFormulation, rigid_objective
from wuerfel_cvx.formulations.velocity import VelocityFormulation
from wuerfel_cvx.geometry import FloatArray, rectangle_corners
from wuerfel_cvx.model import Model, State
from wuerfel_cvx.robustness.determinism import exact_digest

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(not motion_kernel.AVAILABLE, reason="numba is not installed")]

DT = 0.01


def assert_same_bits(compiled: FloatArray, reference: FloatArray) -> None:
    assert compiled.shape == reference.shape and compiled.dtype == reference.dtype
    assert compiled.tobytes() == reference.tobytes()  # signed zeros included


def assert_same_update(monkeypatch: pytest.MonkeyPatch, reference: FloatArray,
                       state: State, solution: FloatArray) -> None:
    """The rigid step from corner velocities, and the corner velocities of body velocities."""
    stepped = both(monkeypatch, lambda: rigid_step(reference, state.points, state.velocities,
                                                   DT))
    assert_same_bits(stepped[1].points, stepped[0].points)
    assert_same_bits(stepped[1].velocities, stepped[0].velocities)
    corners = both(monkeypatch,
                   lambda: RigidFormulation().new_velocities(state, solution, DT))
    assert_same_bits(corners[1], corners[0])


def assert_same_objective(monkeypatch: pytest.MonkeyPatch, model: Model,
                          state: State) -> None:
    """The rigid formulation's weights and target, and the contact reach."""
    objectives = both(monkeypatch, lambda: rigid_objective(model, state, DT))
    for compiled, reference in zip(objectives[1], objectives[0], strict=True):
        assert_same_bits(compiled, reference)
    reaches = both(monkeypatch, lambda: VelocityFormulation().body_reach(model, state, DT))
    assert_same_bits(reaches[1], reaches[0])


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_library_states_move_alike(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    model, states = library_states(name)
    rng = np.random.default_rng(11)
    for state in states:
        assert_same_objective(monkeypatch, model, state)
        assert_same_objective(monkeypatch, model, State(
            state.points, rng.normal(scale=5.0, size=state.velocities.shape)))
        solution = rng.normal(size=3 * model.n_boxes)
        assert_same_update(monkeypatch, model.reference_corners, state, solution)
        resting = State(state.points, -np.zeros_like(state.velocities))  # negative zeros
        assert_same_update(monkeypatch, model.reference_corners, resting,
                           np.zeros(3 * model.n_boxes))


@pytest.mark.parametrize("seed", range(12))
def test_random_boxes_move_alike(monkeypatch: pytest.MonkeyPatch, seed: int) -> None:
    rng = np.random.default_rng(5000 + seed)
    count = int(rng.integers(1, 60))
    sizes = rng.uniform(0.01, 5.0, size=(count, 2)) * 10.0 ** rng.integers(-2, 3, size=(count, 1))
    reference = np.stack([rectangle_corners((0.0, 0.0), w, h, 0.0) for w, h in sizes])
    angles = rng.uniform(-4.0, 4.0, size=count)
    centres = rng.uniform(-50.0, 50.0, size=(count, 2))
    points = np.concatenate([rectangle_corners(c, w, h, a)
                             for c, (w, h), a in zip(centres, sizes, angles, strict=True)])
    points += rng.normal(scale=1e-9, size=points.shape)  # not exactly rigid
    velocities = rng.normal(scale=float(rng.choice([1e-3, 1.0, 30.0])), size=points.shape)
    velocities[rng.random(points.shape) < 0.2] = 0.0
    assert_same_update(monkeypatch, reference, State(points, velocities),
                       rng.normal(size=3 * count))


@pytest.mark.parametrize("formulation", ["rigid", "velocity-baumgarte"])
def test_a_run_is_the_same_with_and_without_the_kernels(
        monkeypatch: pytest.MonkeyPatch, formulation: str) -> None:
    runs = both(monkeypatch, lambda: simulate("two-corner-landing", dt=DT, steps=60,
                                              solver="CLARABEL", formulation=formulation))
    assert exact_digest(runs[1]) == exact_digest(runs[0])
