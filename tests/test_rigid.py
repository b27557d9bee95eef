"""The rigid formulation: the same physics as ``velocity`` in 3 unknowns per square."""

from __future__ import annotations

import numpy as np
import pytest

from oracles import corner_velocity_map, structural_product
from qp_bank import AGREEMENT, qp_bank
from wuerfel_cvx import simulate
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.formulations import RigidFormulation, get_formulation, step_qp
from wuerfel_cvx.formulations.rigid import body_velocities
from wuerfel_cvx.formulations.rows import body_rows
from wuerfel_cvx.solve.paths import solve_step_qp
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.integration


def test_corner_map_reproduces_a_rigid_motion() -> None:
    rng = np.random.default_rng(7)
    traj = simulate("rain-3", steps=1)
    points = traj.points[-1]
    body = rng.normal(size=(3, 3))  # (u_x, u_y, omega) per square
    corners = (corner_velocity_map(points) @ body.ravel()).reshape(-1, 4, 2)
    offsets = points.reshape(-1, 4, 2) - points.reshape(-1, 4, 2).mean(axis=1, keepdims=True)
    # Finite difference of the rigid motion: p(t) = c + u t + R(omega t) r.
    h = 1e-7
    for b in range(3):
        c, s = np.cos(body[b, 2] * h), np.sin(body[b, 2] * h)
        moved = offsets[b] @ np.array([[c, s], [-s, c]]) + body[b, :2] * h
        np.testing.assert_allclose((moved - offsets[b]) / h, corners[b], atol=1e-6)
    masses = np.full((3, 4), 0.25)
    centre, spin = body_velocities(points, corners.reshape(-1, 2), masses)
    np.testing.assert_allclose(centre, body[:, :2], atol=1e-12)
    np.testing.assert_allclose(spin, body[:, 2], atol=1e-12)


def test_rigid_and_velocity_qps_give_the_same_corner_velocities() -> None:
    # With the rods exact, the velocity QP's feasible velocities are the rigid ones and
    # its objective equals the rigid one up to a constant: the minimisers coincide.
    rigid = get_formulation("rigid-baumgarte")
    compared = 0
    for entry in qp_bank():
        if entry.formulation != "velocity" or entry.model.table_mass is not None:
            continue
        # the rigid formulation shares the start-linearised contact rows
        full = solve_step_qp(step_qp(get_formulation("velocity-baumgarte"), entry.model,
                                     entry.state, 0.01), "CLARABEL", "high")
        reduced = solve_step_qp(step_qp(rigid, entry.model, entry.state, 0.01), "CLARABEL",
                                "high")
        assert reduced.verified
        corner = rigid.new_velocities(entry.state, reduced.x, 0.01).ravel()
        # Two verified solutions of the same minimisation (bound derived in
        # test_solver_agreement); the corner map scales by at most 1 + |r| < 2.
        assert np.max(np.abs(corner - full.x[: corner.size])) <= 2 * AGREEMENT, entry.label
        compared += 1
    assert compared >= 8


@pytest.mark.parametrize("scene", ["tilted-drop", "stack-10", "pyramid-3", "overlap-recovery"])
def test_rigid_and_velocity_trajectories_agree(scene: str) -> None:
    steps = 120
    rigid = simulate(scene, steps=steps, formulation="rigid-baumgarte", tol="high")
    velocity = simulate(scene, steps=steps, formulation="velocity-baumgarte", tol="high")
    # Per step the velocities agree within 2 AGREEMENT (above); positions integrate them.
    np.testing.assert_allclose(rigid.points, velocity.points, rtol=0,
                               atol=steps * 0.01 * 2 * AGREEMENT)
    assert rigid.metrics["rod_drift"].max() < 1e-12  # rigid motion: round-off only
    assert (rigid.metrics["n_variables"] == 3 * rigid.points.shape[1] // 4).all()
    assert (rigid.metrics["n_equalities"] == 0).all()


def test_rigid_formulation_refuses_the_heavy_table() -> None:
    from wuerfel_cvx import Scene
    from wuerfel_cvx.step.model import State

    scene = Scene.named("tilted-drop")
    model = Model.from_scene(scene, table_mass=1e6)
    with pytest.raises(InputError, match="fixed tables"):
        step_qp(RigidFormulation(), model, State.initial(scene), 0.01)


def test_structural_product_keeps_cancelled_entries() -> None:
    import scipy.sparse as sp

    left = sp.csr_array(np.array([[1.0, 1.0, 0.0]]))
    right = sp.csr_array(np.array([[1.0, 2.0], [-1.0, 0.0], [5.0, 0.0]]))
    product = structural_product(left, right)
    np.testing.assert_array_equal(product.toarray(), [[0.0, 2.0]])
    assert product.nnz == 2  # the cancelled (0, 0) entry stays in the pattern


@pytest.mark.parametrize("scene", ["pyramid-4", "rain-10"])
def test_body_rows_and_velocities_equal_the_corner_map_products(scene: str) -> None:
    # The rigid build writes G's rows and the corner velocities directly; they must be the
    # sparse products with corner_velocity_map bit for bit (pattern, order and values), so
    # that trajectories do not change.
    from wuerfel_cvx.scenes.scene import Scene
    from wuerfel_cvx.step.contacts import find_contacts
    from wuerfel_cvx.step.model import State

    velocity = get_formulation("velocity")
    traj = simulate(scene, steps=60, formulation="rigid")
    model = Model.from_scene(Scene.named(scene))
    rng = np.random.default_rng(3)
    seen_rows = 0
    for k in (0, 30, 60):
        state = State(traj.points[k], traj.velocities[k])
        contacts = find_contacts(model, state.points, velocity.body_reach(model, state, 0.01))
        corner_rows, _ = velocity.contact_rows(model, model.all_points(state.points), contacts,
                                               0.01)
        ours = body_rows(corner_rows, state.points)
        product = structural_product(corner_rows, corner_velocity_map(state.points))
        assert ours.shape == product.shape and ours.has_canonical_format
        np.testing.assert_array_equal(ours.indptr, product.indptr)
        np.testing.assert_array_equal(ours.indices, product.indices)
        np.testing.assert_array_equal(ours.data, product.data)
        seen_rows += ours.shape[0]
        body = rng.normal(size=3 * model.n_boxes)
        np.testing.assert_array_equal(
            RigidFormulation().new_velocities(state, body, 0.01),
            (corner_velocity_map(state.points) @ body).reshape(-1, 2))
    assert seen_rows > 0


def test_body_rows_keep_a_cancelled_torque() -> None:
    # A contact whose two edge-corner torques cancel exactly keeps the omega entry (0.0).
    points = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    import scipy.sparse as sp

    corner_rows = sp.csr_array(np.array([[0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0]]))
    ours = body_rows(corner_rows, points)
    product = structural_product(corner_rows, corner_velocity_map(points))
    np.testing.assert_array_equal(ours.toarray(), product.toarray())
    assert ours.nnz == product.nnz == 2 and ours.data[-1] == 0.0


def test_a_resting_scene_keeps_one_structure_in_rigid_coordinates() -> None:
    # Constant weights (inertia from the exact squares) and a cancellation-proof pattern
    # keep the structure key constant while nothing moves: one native solver, set up once
    # and updated in place, and on the compiled path one compiled problem.
    traj = simulate("pyramid-4", steps=30, formulation="rigid")
    assert (traj.info["native_setups"], traj.info["native_updates"]) == (1, 29)
    compiled = simulate("pyramid-4", steps=30, formulation="rigid", solve_path="compiled")
    assert compiled.info["compiled_structures"] == 1
    assert compiled.info["steps_reusing_a_compiled_structure"] == 28


CLOSEST = get_formulation("rigid")  # the default: closest-approach rows


@pytest.mark.parametrize("solver", ["CLARABEL", "OSQP", "PIQP"])
def test_rigid_closest_approach_rows_are_the_velocity_formulations_in_three_unknowns(
        solver: str) -> None:
    """``velocity``'s closest-approach rows times the corner map.

    Where the rods hold (they do, to round-off, under the rigid update) both formulations
    pose the same QP, and the polished answers agree to round-off over a run with landings
    and a tilted impact.
    """
    for scene in ("two-corner-landing", "tilted-drop"):
        ours = simulate(scene, dt=0.01, steps=100, solver=solver, formulation=CLOSEST)
        theirs = simulate(scene, dt=0.01, steps=100, solver=solver, formulation="velocity")
        assert ours.metrics["verified"].all()
        np.testing.assert_allclose(ours.points, theirs.points, rtol=0.0, atol=1e-12)


def test_rigid_closest_approach_takes_passes_where_gaps_are_curved() -> None:
    """Falling, spinning bodies need more than one pass, as with ``velocity``.

    The accepted passes hold every contact within the gap tolerance, so penetration stays
    at the velocity formulation's level, below the start-linearised rows'.
    """
    steps = 150
    closest = simulate("rain-20", dt=0.01, steps=steps, formulation=CLOSEST)
    velocity = simulate("rain-20", dt=0.01, steps=steps, formulation="velocity")
    start = simulate("rain-20", dt=0.01, steps=steps, formulation="rigid-baumgarte")
    assert closest.metrics["passes"].max() > 1
    assert closest.metrics["verified"].all()
    assert closest.metrics["penetration_m"].max() <= velocity.metrics["penetration_m"].max() + 1e-9
    assert closest.metrics["penetration_m"].max() < start.metrics["penetration_m"].max()
