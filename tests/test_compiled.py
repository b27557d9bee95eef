"""Compiled, parametrised step QPs: cached by structure, same answers as a fresh declaration."""

from __future__ import annotations

import numpy as np
import pytest

from qp_bank import AGREEMENT, qp_bank
from wuerfel_cvx import simulate
from wuerfel_cvx.solve.cvxpy_forms import structure_key
from wuerfel_cvx.solve.paths import SolvePath, solve_step_qp

pytestmark = pytest.mark.integration

CORE_SOLVERS = ["CLARABEL", "OSQP", "PIQP"]


def test_a_resting_scene_compiles_once() -> None:
    steps = 40
    traj = simulate("stack-10", steps=steps, solver="OSQP", solve_path="compiled")
    # Step 1 is declared plainly (a structure seen once is not worth compiling), step 2
    # compiles it, and every later step re-solves the compiled problem.
    assert traj.info["compiled_structures"] == 1
    assert traj.info["steps_reusing_a_compiled_structure"] == steps - 2


@pytest.mark.parametrize("solver", CORE_SOLVERS)
def test_compiled_and_fresh_declarations_agree_on_every_bank_qp(solver: str) -> None:
    path = SolvePath("compiled", compile_after=1)  # compile every structure at first sight
    for entry in qp_bank():
        fresh = solve_step_qp(entry.build(), solver, "high", path=SolvePath("declared"))
        compiled = solve_step_qp(entry.build(), solver, "high", path=path)
        assert compiled.verified, (entry.label, compiled.residuals)
        # Both are verified solutions of the same strongly convex QP: the agreement bound
        # of the solver-agreement test applies (derived there).
        assert np.max(np.abs(compiled.x - fresh.x)) <= AGREEMENT, entry.label
    assert path.compiled.compiled == len({structure_key(entry.build()) for entry in qp_bank()})


def test_a_compiled_problem_is_reused_with_new_numbers() -> None:
    # Two QPs of the same structure but different numbers: the second reuses the first's
    # compiled problem and still gets its own answer.
    bank = {entry.label: entry for entry in qp_bank()}
    entry = bank["tilted-drop/velocity@55"]
    path = SolvePath("compiled", compile_after=1)
    cache = path.compiled
    qp = entry.build()
    shifted = entry.build()
    shifted.target[:] += 0.5  # same structure, another target
    assert structure_key(qp) == structure_key(shifted)
    first = solve_step_qp(qp, "CLARABEL", "high", path=path)
    second = solve_step_qp(shifted, "CLARABEL", "high", path=path)
    fresh = solve_step_qp(entry.build(), "CLARABEL", "high", path=SolvePath("declared"))
    shifted_fresh = entry.build()
    shifted_fresh.target[:] += 0.5
    second_fresh = solve_step_qp(shifted_fresh, "CLARABEL", "high", path=SolvePath("declared"))
    assert (cache.compiled, cache.reused) == (1, 1)
    assert np.max(np.abs(first.x - fresh.x)) <= AGREEMENT
    assert np.max(np.abs(second.x - second_fresh.x)) <= AGREEMENT
    assert np.max(np.abs(second.x - first.x)) > 100 * AGREEMENT  # really re-solved


@pytest.mark.parametrize("solver", CORE_SOLVERS)
def test_simulation_with_and_without_compilation_agree(solver: str) -> None:
    # 100 steps reach the landing, where contact rows come and go (steps 88 and 95 once
    # hit an OSQP in-place update that OSQP refused, leaving stale data).
    kwargs = {"dt": 0.01, "steps": 100, "solver": solver, "tol": "high"}
    compiled = simulate("tilted-drop", solve_path="compiled", **kwargs)
    fresh = simulate("tilted-drop", solve_path="declared", **kwargs)
    assert compiled.info["compiled_structures"] >= 1
    # Each step's velocities agree within AGREEMENT; positions integrate them over
    # 100 steps of 0.01 s, so they may differ by up to 100 * 0.01 * AGREEMENT.
    np.testing.assert_allclose(compiled.points, fresh.points, rtol=0,
                               atol=100 * 0.01 * AGREEMENT)
    assert compiled.metrics["verified"].all()


def test_cache_keeps_at_most_its_capacity() -> None:
    path = SolvePath("compiled", capacity=2, compile_after=1)
    cache = path.compiled
    entries = qp_bank()[:5]
    for entry in entries:
        solve_step_qp(entry.build(), "OSQP", "default", path=path)
    structures = len({structure_key(entry.build()) for entry in entries})
    assert structures > 2
    assert len(cache) == 2 and cache.compiled == structures
