"""The direct path's compiled gathers (numba) equal its NumPy gathers bit for bit.

On the QP forms of compiled structures (OSQP's and PIQP's) from short runs, the loops of
:mod:`wuerfel_cvx.map_kernel` with ``_numba.enabled`` true and the NumPy path with it false
give the same matrices' nonzeros, right-hand sides and multipliers, at the runs' own numbers
and at random multipliers (negative zeros included); likewise the signed takes of
Clarabel's multipliers.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from kernel_paths import both
from wuerfel_cvx import Scene, Simulation
from wuerfel_cvx.backends._map import scaled
from wuerfel_cvx.compiled import structure_key
from wuerfel_cvx.formulations.qp import StepQP

pytestmark = pytest.mark.integration


def direct_paths(scene: str, formulation: str, solver: str) -> list[tuple[Any, StepQP]]:
    """The direct paths of a short run's QPs whose structure was compiled, with the QPs."""
    sim = Simulation(Scene.named(scene), dt=0.01, solver=solver, formulation=formulation)
    paths = []
    for _ in range(30):
        qp = sim.step().qps[0]
        assert sim.cache is not None
        compiled = sim.cache._problems.get(structure_key(qp))
        if compiled is not None and compiled.direct.get(solver) is not None:
            paths.append((compiled.direct[solver], qp))
    return paths


def assert_same_bits(compiled: np.ndarray, reference: np.ndarray) -> None:
    assert compiled.dtype == reference.dtype and compiled.shape == reference.shape
    assert compiled.tobytes() == reference.tobytes()


def assert_form_alike(monkeypatch: pytest.MonkeyPatch, form: Any, qp: StepQP,
                      rng: np.random.Generator) -> None:
    """A QP form's matrices, right-hand sides and duals, on both paths."""
    nonzeros, _ = form.mapping.values(qp)
    for gather in (form.eq, form.ineq):
        values = both(monkeypatch, lambda g=gather: g.values(nonzeros))
        assert_same_bits(values[1], values[0])
        filled = both(monkeypatch, lambda g=gather: g.fill(nonzeros).data.copy())
        assert_same_bits(filled[1], filled[0])
    for reference, compiled in zip(*both(monkeypatch, lambda: form.rhs(nonzeros)),
                                   strict=True):
        assert_same_bits(compiled, reference)
    rows = form.eq.tags.shape[0] + form.ineq.tags.shape[0]
    y = rng.normal(size=rows)
    y[rng.random(rows) < 0.3] = -0.0
    duals = both(monkeypatch, lambda: form.duals(qp, y[:form.n_eq], y[form.n_eq:]))
    for reference, compiled in zip(*duals, strict=True):
        assert_same_bits(compiled, reference)


@pytest.mark.parametrize("solver", ["OSQP", "PIQP"])
@pytest.mark.parametrize(("scene", "formulation"), [("stack-5", "rigid"),
                                                    ("pyramid-3", "velocity-baumgarte"),
                                                    ("two-corner-landing", "velocity")])
def test_qp_forms_read_the_same_numbers(monkeypatch: pytest.MonkeyPatch, scene: str,
                                        formulation: str, solver: str) -> None:
    rng = np.random.default_rng(21)
    paths = direct_paths(scene, formulation, solver)
    assert paths
    for direct, qp in paths:
        assert_form_alike(monkeypatch, direct.form, qp, rng)


@pytest.mark.parametrize("factor", [1.0, -1.0])
def test_scaled_multipliers_are_the_numpy_products(monkeypatch: pytest.MonkeyPatch,
                                                   factor: float) -> None:
    rng = np.random.default_rng(5)
    multipliers = rng.normal(size=40)
    multipliers[::7] = -0.0
    block = (rng.integers(3, 40, size=25).astype(np.int64), rng.normal(size=25))
    for offset in (0, 3):
        results = both(monkeypatch, lambda o=offset: scaled(multipliers, block, o, factor))
        assert_same_bits(results[1], results[0])
