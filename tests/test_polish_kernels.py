"""The polish's compiled loops give the NumPy code they replaced bit for bit.

The polish (:mod:`wuerfel_cvx.solve.kkt`) guesses an answer's active set, repairs it,
equilibrates, scales and factors the reduced KKT system and refines its solution in
compiled loops (``_sparse.py``, ``solve/residual_kernel.py``); the NumPy code they replaced
is kept in ``tests/reference_kernels.py``.  Compared on the step QPs of short runs (at the
solvers' answers and perturbed ones, also as the general route with ``+inf`` upper
bounds) and on random QPs with finite upper bounds, rows with ``h = u`` among them.  The
golden digests (``tests/test_determinism.py``) pin whole runs.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

import reference_kernels as reference
from wuerfel_cvx import _sparse, simulate
from wuerfel_cvx.formulations.qp import StepQP, declare_qp
from wuerfel_cvx.solve import kkt
from wuerfel_cvx.step.contacts import Contacts

pytestmark = pytest.mark.integration

CASES = [("stack-5", "rigid", 30), ("pyramid-4", "rigid", 30),
         ("rain-10", "velocity-baumgarte", 30), ("two-corner-landing", "seed", 30)]


def _answers(scene: str, formulation: str, steps: int) -> list[tuple[StepQP, np.ndarray,
                                                                     np.ndarray]]:
    """The QPs of a short run with their (polished) answers ``x``, ``z``."""
    seen: list[tuple[StepQP, np.ndarray, np.ndarray]] = []
    simulate(scene, dt=0.01, steps=steps, solver="CLARABEL", formulation=formulation,
             observer=lambda step, qp, solution: seen.append(
                 (qp, solution.x, solution.ineq_dual)))
    return seen


def _random_qp(rng: np.random.Generator) -> StepQP:
    """Six unknowns, ten rows: some one-sided, some with a finite upper bound, some ``h = u``."""
    n, m = 6, 10
    rows = sp.random_array((m, n), density=0.5, random_state=rng) + sp.eye_array(m, n)
    lower = rng.normal(size=m)
    upper = lower + np.where(rng.random(m) < 0.4, np.inf, rng.uniform(0.0, 1.0, m))
    upper[:2] = lower[:2]  # two rows held at h = u
    return declare_qp(rng.uniform(0.5, 2.0, n), rng.normal(size=n), sp.csr_array((0, n)),
                      np.zeros(0), sp.csr_array(rows), lower, Contacts.empty(),
                      ineq_upper=upper)


def _assert_same_rules(qp: StepQP, x: np.ndarray, z: np.ndarray) -> None:
    """The guess (both margins) and its repair at ``(x, z)`` are the references'."""
    _, scales = kkt._checked(qp, x, np.zeros(qp.n_equalities), z)
    for margin in (1.0, kkt.CLEAR_MARGIN):
        active = kkt.guess_active_set(qp, x, z, scales, margin)
        lower, upper = reference.guess_active_set(qp, x, z, scales.primal, scales.dual, margin)
        assert np.array_equal(active.lower, lower) and np.array_equal(active.upper, upper)
        ours = kkt._repaired(qp, active, x, -z, scales)  # the wrong signs: rows to free
        theirs = reference.repaired(qp, lower, upper, x, -z, kkt.ROUND_OFF * scales.dual,
                                    kkt.ROUND_OFF * scales.primal)
        assert (ours is None) == (theirs is None)
        if ours is not None and theirs is not None:
            assert np.array_equal(ours.lower, theirs[0])
            assert np.array_equal(ours.upper, theirs[1])


def _assert_same_system(qp: StepQP, active: kkt.ActiveSet, start: np.ndarray) -> None:
    """Equilibration, scaling, factor and refinement of the reduced system: the references'."""
    matrix, rhs = kkt.reduced_kkt(qp, active)
    n = qp.n_variables
    arrays = (matrix.data, matrix.indices, matrix.indptr)
    scale = _sparse.equilibration(*arrays, n)
    assert np.array_equal(scale, reference.equilibration(matrix, n))
    scaled = _sparse.canonical_csc(reference.scaled(matrix, scale), matrix.indices,
                                   matrix.indptr, matrix.shape)
    new_of_old, shift = reference.regularisation(scaled, n, kkt.REGULARISATION)
    *expected, factored = _sparse.ldl_factor(*_sparse.permuted_upper(
        scaled.data, scaled.indices, scaled.indptr, new_of_old, shift))
    point, their_scale, *factor, their_new_of_old, ours_factored = (
        _sparse.equilibrated_solution(*arrays, n, np.zeros(0, dtype=np.int64), rhs, start,
                                      kkt.REGULARISATION, kkt.REFINEMENTS))
    assert np.array_equal(their_scale, scale)
    assert ours_factored == factored
    if not factored:
        return
    assert np.array_equal(their_new_of_old, new_of_old)
    for ours, theirs in zip(factor, expected, strict=True):
        assert np.array_equal(ours, theirs)
    l_ptr, l_rows, l_data, inverse_pivot = expected
    assert np.array_equal(point, scale * reference.refined(
        scaled, (l_ptr, l_rows, l_data, inverse_pivot), new_of_old, scale * rhs,
        start / scale, kkt.REFINEMENTS, _sparse.ldl_solve))


def _assert_one_call_solves_the_system(qp: StepQP, active: kkt.ActiveSet,
                                       answer: tuple[np.ndarray, np.ndarray],
                                       start: np.ndarray) -> None:
    """``_sparse.reduced_solution`` (a small system's one call): the assembled system's point."""
    n, n_eq = qp.n_variables, qp.n_equalities
    matrix, rhs = kkt.reduced_kkt(qp, active)
    expected = kkt._refined_solution(matrix, n, rhs, start)
    point = kkt._solve_on(qp, active, answer[0], np.zeros(n_eq), answer[1])
    assert (point is None) == (expected is None or not np.isfinite(expected).all())
    if point is None or expected is None:
        return
    z = np.zeros(qp.n_inequalities)
    z[active.rows] = -expected[n + n_eq:]
    for ours, theirs in zip(point, (expected[:n], expected[n:n + n_eq], z), strict=True):
        assert np.array_equal(ours, theirs)


@pytest.mark.parametrize(("scene", "formulation", "steps"), CASES)
def test_the_polish_kernels_are_the_references_on_step_qps(scene: str, formulation: str,
                                                           steps: int) -> None:
    rng = np.random.default_rng(7)
    for qp, x, z in _answers(scene, formulation, steps)[::3]:
        noisy_x = x + rng.normal(scale=1e-6, size=x.shape)
        noisy_z = z + rng.normal(scale=1e-3, size=z.shape)
        for route in (qp, reference.general_route(qp)):
            _assert_same_rules(route, x, z)
            _assert_same_rules(route, noisy_x, noisy_z)
        _, scales = kkt._checked(qp, x, np.zeros(qp.n_equalities), z)
        active = kkt.guess_active_set(qp, x, z, scales)
        start = np.concatenate([noisy_x, np.zeros(qp.n_equalities), -noisy_z[active.rows]])
        _assert_same_system(qp, active, start)
        _assert_one_call_solves_the_system(qp, active, (noisy_x, noisy_z), start)


@pytest.mark.parametrize(("scene", "formulation", "steps"), CASES)
def test_the_compiled_attempts_are_the_numpy_routes(scene: str, formulation: str, steps: int,
                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A small common QP's polish is its NumPy route's bit for bit.

    Compiled: the check, guess and attempts (``first_polish``, ``attempt``); at exact,
    perturbed and wrong answers.
    """
    rng = np.random.default_rng(11)
    cases = []
    for qp, x, z in _answers(scene, formulation, steps)[::3]:
        y = np.zeros(qp.n_equalities)
        for size in (0.0, 1e-9, 1e-6, 1e-3):
            cases.append((qp, x + rng.normal(scale=size, size=x.shape), y,
                          z + rng.normal(scale=1e3 * size, size=z.shape)))
    _assert_same_polishes(cases, monkeypatch)


def test_the_compiled_attempts_are_the_numpy_routes_on_random_qps(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """As above, on random answers to random QPs with parallel rows: rejected ones too."""
    _assert_same_polishes([_random_common_case(seed) for seed in range(60)], monkeypatch)


def _random_common_case(seed: int) -> tuple[StepQP, np.ndarray, np.ndarray, np.ndarray]:
    """A QP of four unknowns, one equality and 18 rows (six parallel to others), an answer."""
    rng = np.random.default_rng(seed)
    n, m = 4, 12
    cyclic = sp.csr_array((np.ones(m), (np.arange(m), np.arange(m) % n)), shape=(m, n))
    rows = sp.csr_array(sp.random_array((m, n), density=0.5, random_state=rng) + cyclic)
    rows = sp.csr_array(sp.vstack([rows, -rows[:3], 2.0 * rows[3:6]]))
    qp = declare_qp(rng.uniform(0.5, 2.0, n), rng.normal(size=n),
                    sp.csr_array(rng.normal(size=(1, n))), rng.normal(size=1), rows,
                    rng.normal(size=rows.shape[0]), Contacts.empty())
    z = np.abs(rng.normal(size=rows.shape[0])) * (rng.random(rows.shape[0]) < 0.5)
    return qp, rng.normal(size=n), rng.normal(size=1), z


def _assert_same_polishes(cases: list[tuple[StepQP, np.ndarray, np.ndarray, np.ndarray]],
                          monkeypatch: pytest.MonkeyPatch) -> None:
    """``polish`` of each case compiled (small common QPs) and by the NumPy route: equal."""
    compiled = [kkt.polish(*case) for case in cases]
    monkeypatch.setattr(kkt, "_small_common", lambda _: False)
    for case, ours in zip(cases, compiled, strict=True):
        theirs = kkt.polish(*case)
        assert (ours.outcome, ours.reason) == (theirs.outcome, theirs.reason)
        for field in ("x", "eq_dual", "ineq_dual"):
            assert getattr(ours, field).tobytes() == getattr(theirs, field).tobytes()
        assert np.array_equal(ours.active.lower, theirs.active.lower)
        assert np.array_equal(ours.active.upper, theirs.active.upper)
        assert dataclasses.astuple(ours.residuals) == dataclasses.astuple(theirs.residuals)


def test_the_checks_scales_are_the_general_codes() -> None:
    """The compiled check's scales (common QPs) equal ``_scales``'s NumPy ones."""
    for qp, x, z in _answers("stack-5", "rigid", 30):
        y = np.zeros(qp.n_equalities)
        assert kkt._checked(qp, x, y, z)[1] == kkt._scales(reference.general_route(qp), x, y, z)


@pytest.mark.parametrize("seed", range(20))
def test_the_active_set_rules_are_the_references_with_upper_bounds(seed: int) -> None:
    rng = np.random.default_rng(seed)
    qp = _random_qp(rng)
    x = rng.normal(size=qp.n_variables)
    z = rng.normal(size=qp.n_inequalities) * (rng.random(qp.n_inequalities) < 0.7)
    _assert_same_rules(qp, x, z)
    _assert_same_rules(dataclasses.replace(qp, ineq_upper=None), x, z)
