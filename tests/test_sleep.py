"""Islands and sleep: separate islands are separate QPs; sleeping islands wake on contact."""

from __future__ import annotations

import numpy as np
import pytest

from qp_bank import AGREEMENT
from wuerfel_cvx import Scene, Square, simulate
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.formulations import get_formulation, step_qp
from wuerfel_cvx.scenes.library import FLOOR
from wuerfel_cvx.settings import Settings
from wuerfel_cvx.simulate import ASLEEP
from wuerfel_cvx.solve.paths import solve_step_qp
from wuerfel_cvx.step.contacts import find_contacts
from wuerfel_cvx.step.model import Model, State
from wuerfel_cvx.step.sleep import SleepSettings, island_labels, island_members

pytestmark = pytest.mark.integration

DT = 0.01


def test_islands_are_the_connected_stacks(two_stacks_and_a_faller: Scene) -> None:
    scene = two_stacks_and_a_faller
    model, state = Model.from_scene(scene), State.initial(scene)
    contacts = find_contacts(model, state.points, get_formulation("velocity").body_reach(
        model, state, DT))
    labels = island_labels(model.n_boxes, contacts)
    assert len(set(labels[:3])) == 1 and len(set(labels[3:6])) == 1
    assert len({labels[0], labels[3], labels[6]}) == 3  # the floor does not connect


def test_separate_islands_solve_to_the_joint_qps_answer(two_stacks_and_a_faller: Scene) -> None:
    scene = two_stacks_and_a_faller
    model, state = Model.from_scene(scene), State.initial(scene)
    velocity = get_formulation("velocity")
    joint = solve_step_qp(step_qp(velocity, model, state, DT), "CLARABEL", "high")
    assert joint.verified
    for squares in (np.arange(0, 3), np.arange(3, 6), np.arange(6, 7)):
        corners = (4 * squares[:, None] + np.arange(4)).ravel()
        part = State(state.points[corners], state.velocities[corners])
        alone = solve_step_qp(step_qp(velocity, model.subset(squares), part, DT), "CLARABEL",
                              "high")
        assert alone.verified
        joint_part = joint.x.reshape(-1, 2)[corners].ravel()
        # Both are verified solutions of the same island's rows (bound derived in
        # test_solver_agreement).
        assert np.max(np.abs(alone.x - joint_part)) <= AGREEMENT


def test_island_members_groups_squares_by_island() -> None:
    labels = np.array([2, 0, 2, 1, 0, 1])
    members = island_members(labels)
    assert [m.tolist() for m in members] == [[0, 2], [1, 4], [3, 5]]
    awake = np.array([True, False, True, False, False, True])
    assert [m.tolist() for m in island_members(labels, awake)] == [[0, 2], [5]]
    assert island_members(labels, np.zeros(6, dtype=bool)) == []


def test_simulate_with_islands_solves_one_qp_per_island_with_the_joint_answer(
        two_stacks_and_a_faller: Scene) -> None:
    scene = two_stacks_and_a_faller
    seen: list[tuple[int, int]] = []
    islands = simulate(scene, steps=1, tol="high", islands=True,
                       observer=lambda step, qp, solution: seen.append(
                           (qp.n_variables, qp.n_inequalities)))
    joint = simulate(scene, steps=1, tol="high")
    # Three QPs: the two 3-stacks (9 unknowns each: 3 per body) and the faller (3, no
    # contacts).
    assert [n for n, _ in seen] == [9, 9, 3] and seen[2][1] == 0
    row, joint_row = islands.metrics.iloc[0], joint.metrics.iloc[0]
    for column in ("n_variables", "n_equalities", "n_inequalities", "n_contacts"):
        assert row[column] == joint_row[column]
    assert row["verified"] and row["solver_time_s"] > 0
    # Verified solutions of the same rows: new velocities within AGREEMENT (m/s), and
    # positions, moved rigidly by dt times them, within dt * AGREEMENT (m) up to round-off.
    assert np.max(np.abs(islands.velocities[1] - joint.velocities[1])) <= 2 * AGREEMENT
    assert np.max(np.abs(islands.points[1] - joint.points[1])) <= DT * 2 * AGREEMENT + 1e-12


def test_islands_keep_their_own_compiled_structures_and_sleep_still_works() -> None:
    # The resting 5-stack repeats its structure while the faller is alone; once it lands
    # the merged island is a new structure.  With sleep the stack sleeps, then wakes.
    steps = 250
    traj = simulate(drop_on_stack(), steps=steps, tol="high", sleep=SleepSettings(),
                    islands=True)
    joint = simulate(drop_on_stack(), steps=steps, tol="high", sleep=SleepSettings())
    sizes = traj.metrics["n_variables"].to_numpy()
    np.testing.assert_array_equal(sizes, joint.metrics["n_variables"].to_numpy())
    assert traj.metrics["verified"].all()
    np.testing.assert_array_equal(traj.metrics["status"] == ASLEEP,
                                  joint.metrics["status"] == ASLEEP)
    # Each island is cached by its own structure: the stack, the lone faller and the
    # landed pile; a step with both islands awake re-solves two of them.
    assert traj.info["native_setups"] <= 3
    assert traj.info["native_updates"] > joint.info["native_updates"]
    # Same physics: the landing square rests on the stack (to solver tolerance).
    top = traj.points[-1, 20:24]
    np.testing.assert_allclose(top[:, 1].min(), 5.0, atol=1e-6)
    np.testing.assert_allclose(traj.points, joint.points, rtol=0, atol=1e-6)


def drop_on_stack() -> Scene:
    stack = tuple(Square(center=(0.0, 0.5 + k)) for k in range(5))
    return Scene("drop-on-stack", (*stack, Square(center=(0.2, 9.0))), (FLOOR,))


def test_a_square_dropped_on_a_sleeping_stack_wakes_it_and_lands_on_it() -> None:
    steps = 250
    sleeping = simulate(drop_on_stack(), steps=steps, tol="high", sleep=SleepSettings())
    awake = simulate(drop_on_stack(), steps=steps, tol="high")
    sizes = sleeping.metrics["n_variables"].to_numpy()
    # The stack sleeps after 0.5 s still: only the falling square is in the QP ...
    alone = np.flatnonzero(sizes == 3)  # 3 unknowns per body
    assert alone.size > 20 and alone[0] == 50
    # ... until it reaches the stack, which wakes as one island with it (6 squares).
    assert np.any(sizes[alone[-1] + 1:] == 18)
    # Sleeping changed nothing: the stack was at rest (to the sleep speed 1e-4 m/s).
    np.testing.assert_allclose(sleeping.points, awake.points, rtol=0, atol=1e-8)
    top = sleeping.points[-1, 20:24]
    np.testing.assert_allclose(top[:, 1].min(), 5.0, atol=1e-6)  # resting on the stack
    assert sleeping.metrics["penetration_m"].max() < 1e-6


def test_a_settled_stack_sleeps_and_stays_exactly_still() -> None:
    traj = simulate("stack-10", steps=120, sleep=SleepSettings(time=0.5))
    status = traj.metrics["status"].to_numpy()
    assert (status[:50] != ASLEEP).all() and (status[50:] == ASLEEP).all()
    asleep = traj.metrics[traj.metrics["status"] == ASLEEP]
    assert (asleep["n_variables"] == 0).all()
    frozen = traj.points[51:]
    assert np.array_equal(frozen, np.broadcast_to(frozen[0], frozen.shape))
    assert not traj.velocities[51:].any()


def test_sleep_true_means_the_default_sleep_settings_and_a_wrong_type_is_named() -> None:
    assert Settings(sleep=True).sleep == SleepSettings()
    assert Settings(sleep=False).sleep is None
    with pytest.raises(InputError, match="sleep"):
        Settings(sleep="yes")  # type: ignore[arg-type]
