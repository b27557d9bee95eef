"""The friction targets' measurements on scenes whose answer is known."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.lab.bench.friction_targets import (
    RAMP_TOLERANCE,
    _longest_run,
    displacement,
    ramp_rows,
    render,
)
from wuerfel_cvx.scenes.library import slope_acceleration, slope_scene

pytestmark = pytest.mark.integration


def test_longest_run_finds_the_longest_stretch_of_true() -> None:
    mask = np.array([0, 1, 1, 0, 1, 1, 1, 0, 1], dtype=bool)
    assert _longest_run(mask) == (4, 7)
    assert _longest_run(np.zeros(4, dtype=bool)) == (0, 0)
    assert _longest_run(np.ones(3, dtype=bool)) == (0, 3)


def test_ramp_fit_of_a_box_sliding_down_a_slope_is_g_sin_minus_mu_cos() -> None:
    scene = slope_scene(0.4, 0.3)
    trajectory = simulate(scene, dt=1.0 / 240.0, steps=120)
    (row,) = ramp_rows(trajectory, scene)
    assert row["mu"] == pytest.approx(0.3)
    assert row["expected"] == pytest.approx(slope_acceleration(0.4, 0.3))
    assert row["fit_s"] >= 0.4  # the box lies flat from the start: almost the whole run
    assert row["fitted"] == pytest.approx(row["expected"], rel=RAMP_TOLERANCE["ccp"])
    # a box that stays put on a steeper friction has moved nothing measurable
    still = simulate(slope_scene(0.4, 0.6), dt=1.0 / 60.0, steps=60)
    assert displacement(still, 0.0) <= 1e-4
    text = render(pd.DataFrame([{"kind": "ramp", "scene": "friction-slope",
                                 "engine": "wuerfel_cvx", "model": "ccp",
                                 "solver": "CLARABEL", "outcome": "ok", "wall_s": 1.0,
                                 "coulomb_steps": np.nan, "coulomb_converged": np.nan,
                                 **row}]))
    assert "| ccp | CLARABEL | 0 |" in text and "met" in text


def test_measure_runs_only_the_scenes_asked_for(monkeypatch: pytest.MonkeyPatch) -> None:
    from wuerfel_cvx.lab.bench import friction_targets

    ran: list[str] = []
    monkeypatch.setattr(friction_targets, "_run",
                        lambda scene, *args: (ran.append(scene), (None, "not run"))[1])
    monkeypatch.setattr(friction_targets, "available_peers", lambda: [])
    rows = list(friction_targets.measure(quick=True, scenes=["card-house"]))
    assert set(ran) == {"card-house"} and {row["scene"] for row in rows} == {"card-house"}
    assert len(rows) == len(friction_targets.MODELS) * len(friction_targets.SOLVERS)
    assert list(friction_targets.measure(quick=True, scenes=["no-such-scene"])) == []


def test_a_run_that_stopped_is_reported_failed_not_standing() -> None:
    from wuerfel_cvx.lab.bench.friction_targets import _verdict

    record = {"outcome": "step 4: solver OSQP failed with status 'user_limit'", "moved": 0.0}
    assert _verdict(record) == "failed"
    assert _verdict({"outcome": "ok", "moved": 0.0}) == "stands"
    assert _verdict({"outcome": "ok", "moved": 2e-4}) == "moves"
