"""The speed suites measure what the speed targets name.

``perf`` holds the small scenes of the modelling-time target (``tilted-drop``,
``stack-10``) in every QP formulation and solver; ``scaling`` holds Box2D's large pyramid
(``field-pyramid-100``: ``large-pyramid``, 5050 squares) and a settled pile of several sizes
up to it in one configuration, so that the scaling exponent can be fitted on a pile at rest.
"""

from __future__ import annotations

import pytest

from wuerfel_cvx.lab.bench.suite import Suite
from wuerfel_cvx.scenes.scene import Scene
from wuerfel_cvx.solve.paths import SOLVE_PATHS

pytestmark = pytest.mark.unit


def test_perf_times_the_small_scenes_in_every_formulation_solver_and_path() -> None:
    points = Suite.named("perf").points
    formulations = {"velocity", "velocity-baumgarte", "rigid"}
    solvers = {"CLARABEL", "OSQP", "PIQP", "PROXQP", "DAQP", "HIGHS"}
    for scene in ("tilted-drop", "stack-10"):
        configurations = {(p.formulation, p.solver, p.solve_path)
                          for p in points if p.scene == scene}
        assert configurations == {(formulation, solver, path) for formulation in formulations
                                  for solver in solvers for path in SOLVE_PATHS}


def test_scaling_fits_a_settled_pile_up_to_the_large_pyramid() -> None:
    points = [p for p in Suite.named("scaling").points
              if p.scene.startswith("field-pyramid-") and p.formulation == "rigid"]
    by_solver: dict[str, set[int]] = {}
    for point in points:
        by_solver.setdefault(point.solver, set()).add(
            len(Scene.named(point.scene).squares))
    assert 5050 in by_solver["PIQP"]  # field-pyramid-100, Box2D's large_pyramid
    assert len(by_solver["PIQP"]) >= 5  # enough sizes for a fitted exponent
    assert all(point.reference == "rest" for point in points)  # a pile at rest
