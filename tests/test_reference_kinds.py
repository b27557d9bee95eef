"""A suite's reference kinds measure what they say: ``rest`` only for scenes that start at rest.

The friction suite once took the initial state as the exact solution of ``vertical-stack``,
whose boxes start 0.1 m apart: every run's "error" was the 1.45 m its top box falls before
it rests.  A scene that starts apart is measured after it settles (``settled``), or against
the dt/8 run.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.lab.bench import schema
from wuerfel_cvx.lab.bench.suite import GridPoint, Suite
from wuerfel_cvx.lab.bench.sweep import run_sweep
from wuerfel_cvx.simulate import resolve_scene

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
SUITES = sorted(BENCHMARKS.glob("*.toml"))

REST_STEPS = 2
"""Steps of each resting scene that must stay put."""
REST_SHARE = 1e-3
"""A scene at rest moves less than this share of a free fall over those steps (m/m)."""


def _points() -> list[GridPoint]:
    return [point for path in SUITES for point in Suite.from_toml(path).points]


def _rest_cases() -> list[tuple[str, float]]:
    """Each scene and time step (s) of a grid point of a bundled suite with reference ``rest``."""
    cases = {(point.scene_input, point.dt) for point in _points() if point.reference == "rest"}
    return sorted(cases)


REST_CASES = _rest_cases()


@pytest.mark.unit
def test_the_suites_have_resting_and_settling_points() -> None:
    assert SUITES and len(REST_CASES) > 20
    settled = {point.scene for point in _points() if point.reference == "settled"}
    assert {"vertical-stack", "card-house", "high-mass-ratio-1",
            "high-mass-ratio-2"} <= settled
    for point in _points():
        if point.reference == "settled":
            assert 0 < point.settle < point.duration


@pytest.mark.integration
@pytest.mark.parametrize(("scene", "dt"), REST_CASES,
                         ids=[f"{Path(scene).stem}-dt{dt:.4g}" for scene, dt in REST_CASES])
def test_a_scene_measured_from_rest_starts_at_rest(scene: str, dt: float) -> None:
    """Its first steps move it by a thousandth of a free fall at most.

    A box 0.1 m above its support falls ``g dt^2`` in one step (2.7 mm at dt 1/60); a
    toppling column tips by half a millimetre; a stack at rest moves by 1e-9 m.  Rigid
    coordinates and PIQP: the fastest configuration, so the 5050-box pyramid takes seconds.
    """
    loaded = resolve_scene(scene)
    trajectory = simulate(loaded, dt=dt, steps=REST_STEPS, formulation="rigid", solver="PIQP")
    moved = float(np.max(np.linalg.norm(trajectory.points - trajectory.points[:1], axis=-1)))
    free_fall = 0.5 * float(np.linalg.norm(loaded.gravity)) * (REST_STEPS * dt) ** 2
    assert moved <= REST_SHARE * free_fall, (
        f"{scene} moves {moved:.3g} m in {REST_STEPS} steps of {dt:g} s: it does not start "
        "at rest; give it reference 'settled' (with a settle time) or 'dt/8'")


def _suite(**block: object) -> dict[str, object]:
    return {"name": "tiny", "defaults": {"duration": 0.05, "dts": [0.01]},
            "grid": [{"scenes": ["tilted-drop"], "solvers": ["CLARABEL"], **block}]}


@pytest.mark.unit
@pytest.mark.parametrize(("block", "message"), [
    ({"reference": "settled"}, "needs 0 < settle < duration"),
    ({"reference": "settled", "settle": 0.05}, "needs 0 < settle < duration"),
    ({"reference": "settled", "settle": -1.0}, "needs 0 < settle < duration"),
    ({"reference": "rest", "settle": 0.02}, "only with reference 'settled'"),
])
def test_a_settling_time_is_checked(block: dict[str, object], message: str) -> None:
    with pytest.raises(InputError, match=message) as caught:
        Suite.from_dict(_suite(**block), source="bad.toml")
    assert caught.value.field == "grid[0].settle"


@pytest.mark.integration
def test_settled_reference_measures_the_motion_after_the_settling_time(tmp_path: Path) -> None:
    suite = Suite.from_dict(_suite(reference="settled", settle=0.02, compare_every=0))
    (point,) = suite.points
    assert (point.settle, point.reference_label) == (0.02, "settled 0.02 s")
    summary = run_sweep(suite, tmp_path, progress=False, echo=lambda _: None)
    row = schema.read_results(summary.results).iloc[0]
    points = simulate("tilted-drop", dt=0.01, steps=5).points
    after = float(np.max(np.linalg.norm(points[2:] - points[2], axis=-1)))
    from_start = float(np.max(np.linalg.norm(points - points[0], axis=-1)))
    assert row["reference_kind"] == "settled 0.02 s"
    assert math.isclose(row["trajectory_error"], after, rel_tol=1e-6)
    assert row["trajectory_error"] < from_start  # not the fall before the settling time
