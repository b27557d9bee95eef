"""A run's state metrics, computed for all states at once, are the per-state functions' bits."""

from __future__ import annotations

import numpy as np
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.step.metrics import (
    STATE_COLUMNS,
    kinetic_energy,
    potential_energy,
    rod_length_drift,
    state_metrics,
)
from wuerfel_cvx.step.model import State

pytestmark = pytest.mark.integration


@pytest.mark.parametrize("scene", ["tilted-drop", "stack-10", "pyramid-10"])
def test_state_metrics_are_the_per_state_functions_bit_for_bit(scene: str) -> None:
    run = simulate(scene, steps=30)
    model = run.model()
    assert model is not None
    rng = np.random.default_rng(7)  # and states no run reaches: any rounding would show
    shaken = (run.points + rng.normal(size=run.points.shape),
              run.velocities + 3.0 * rng.normal(size=run.velocities.shape))
    for points, velocities in ((run.points, run.velocities), shaken):
        columns = state_metrics(model, points, velocities)
        assert tuple(columns) == STATE_COLUMNS
        for index, (state_points, state_velocities) in enumerate(zip(points, velocities,
                                                                     strict=True)):
            state = State(state_points, state_velocities)
            kinetic, potential = kinetic_energy(model, state), potential_energy(model, state)
            assert columns["rod_drift"][index] == rod_length_drift(model, state_points)
            assert columns["kinetic_energy_J"][index] == kinetic
            assert columns["potential_energy_J"][index] == potential
            assert columns["total_energy_J"][index] == kinetic + potential


def test_a_runs_metrics_hold_its_states_energies() -> None:
    run = simulate("tilted-drop", steps=20)
    model = run.model()
    assert model is not None
    last = State(run.points[-1], run.velocities[-1])
    row = run.metrics.iloc[-1]
    assert row["kinetic_energy_J"] == kinetic_energy(model, last)
    assert row["rod_drift"] == rod_length_drift(model, last.points)
    assert run.metrics["total_energy_J"].dtype == np.float64


def test_a_state_with_a_nan_corner_drifts_nan_as_the_per_state_function() -> None:
    run = simulate("stack-10", steps=2)
    model = run.model()
    assert model is not None
    points = run.points.copy()
    points[1, 5, 0] = np.nan  # a rod of the second box in the second state
    drift = state_metrics(model, points, run.velocities)["rod_drift"]
    assert np.isnan(drift[1]) and np.isnan(rod_length_drift(model, points[1]))
    assert drift[0] == rod_length_drift(model, points[0])
    assert drift[2] == rod_length_drift(model, points[2])
