"""Generated scenes with friction keep every invariant of the property checks.

The checks (:func:`wuerfel_cvx.lab.robustness.properties.check_run`) are the frictionless
ones: the cone rows keep their normal rows' right-hand sides, and ``coulomb``'s state is
its last contact QP's, accepted by the same gap test (``docs/friction.md``,
``docs/coulomb.md``), so the penetration and energy bounds are unchanged.  Friction must
not add energy or depth beyond them.
"""

from __future__ import annotations

import numpy as np
import pytest

from wuerfel_cvx.lab.robustness.properties import random_scene, run_property_sweep

pytestmark = pytest.mark.integration


def test_the_generator_draws_friction_on_request_only() -> None:
    plain = random_scene(np.random.default_rng(7))
    rough = random_scene(np.random.default_rng(7), friction=True)
    assert all(body.friction == 0.0 for body in plain.bodies)
    assert any(body.friction > 0.0 for body in rough.bodies)


@pytest.mark.parametrize("model", ["ccp", "coulomb"])
def test_generated_scenes_with_friction_keep_the_invariants(model: str) -> None:
    result = run_property_sweep(4, seed=7, steps=120, friction=True, friction_model=model)
    assert result.tried == 4
    assert not result.failures, [failure.problems for failure in result.failures]
