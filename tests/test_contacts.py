"""Contact finding: the seed's sector rule, corner ties, the broad phase, tables.

The search's per-pair manifold rule itself is tested in ``test_contacts_manifold.py``; the
sector rule below is the per-corner geometry it replaced, still the seed's section 2.3.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from manifold_oracle import manifold_rows
from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.formulations import get_formulation, step_qp
from wuerfel_cvx.scenes.geometry import edge_distances, polygon_overlap_depth, square_corners
from wuerfel_cvx.step.contacts import Contacts, find_contacts
from wuerfel_cvx.step.model import Model, State

pytestmark = pytest.mark.integration


def seed_sector(point: np.ndarray, center: np.ndarray, angle: float) -> int:
    """Edge index by the seed's full-circle angle around the centre (section 2.3).

    Edge e joins corners e and e+1; for a counter-clockwise square of orientation
    ``angle`` its sector spans body angles (-135 + 90 e, -45 + 90 e] degrees.
    """
    d = point - center
    body = math.degrees(math.atan2(d[1], d[0]) - angle)
    return int(((body + 135.0) % 360.0) // 90.0)


def test_largest_distance_edge_is_the_seed_sector_for_squares() -> None:
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(2000):
        center, size, angle = rng.normal(size=2), rng.uniform(0.2, 3), rng.uniform(-4, 4)
        corners = square_corners(center, size, angle)
        point = center + rng.normal(scale=2 * size, size=2)
        distances = edge_distances(point[None, :], corners)[0]
        top_two = np.sort(distances)[-2:]
        if top_two[1] - top_two[0] < 1e-9:
            continue  # on a diagonal: the tie is handled separately
        assert int(np.argmax(distances)) == seed_sector(point, center, angle)
        checked += 1
    assert checked > 1900


def test_corner_on_corner_is_held_by_the_face_it_rests_on() -> None:
    scene = Scene.named("stack-2")
    model = Model.from_scene(scene)
    contacts = find_contacts(model, scene.initial_points(), 1e-3)
    # Upper square (corners 4..7): its bottom corners 4, 5 rest exactly on the lower
    # square's top corners, at a tie between its top face (3 -> 2) and its sides; the
    # pair's normal is vertical, so both are held by the top face.
    upper_on_lower = contacts.point_body == 1
    assert set(contacts.point[upper_on_lower]) == {4, 5}
    assert set(zip(contacts.edge_i[upper_on_lower], contacts.edge_j[upper_on_lower],
                   strict=True)) == {(3, 2)}
    lower_on_upper = (contacts.point_body == 0) & (contacts.edge_body == 1)
    assert set(zip(contacts.edge_i[lower_on_upper], contacts.edge_j[lower_on_upper],
                   strict=True)) == {(5, 4)}


def all_pairs_contacts(model: Model, points: np.ndarray, margin: float) -> set[tuple[int, ...]]:
    """Reference: every body pair, no broad phase, the same manifold rule, one pair a time."""
    corners = model.all_points(points).reshape(-1, 4, 2)
    pairs = np.array([(w, b) for w in range(model.n_bodies) for b in range(model.n_bodies)
                      if w != b])
    rows = manifold_rows(corners, model.n_boxes, pairs, np.full(model.n_bodies, margin))
    return {row[:3] for row in rows}


def as_set(contacts: Contacts) -> set[tuple[int, ...]]:
    return set(zip(contacts.point.tolist(), contacts.edge_i.tolist(), contacts.edge_j.tolist(),
                   strict=True))


@pytest.mark.parametrize("step", [0, 60, 120, 200])
def test_broad_phase_finds_what_all_pairs_finds(step: int) -> None:
    scene = Scene.named("rain-12")
    traj = simulate(scene, dt=0.01, steps=step)
    model = Model.from_scene(scene)
    margin = 0.05  # per body, so 0.1 m for a pair
    assert as_set(find_contacts(model, traj.points[-1], margin)) == all_pairs_contacts(
        model, traj.points[-1], margin)


def test_tables_are_constants_not_variables() -> None:
    scene = Scene.named("stack-3")
    model = Model.from_scene(scene)
    qp = step_qp(get_formulation("velocity"), model, State.initial(scene), 0.01)
    assert qp.n_variables == 2 * 4 * scene.n_boxes
    assert qp.n_equalities == 5 * scene.n_boxes


def test_heavy_table_variant_holds_the_table_and_matches_the_fixed_one() -> None:
    scene = Scene.named("tilted-drop")
    heavy = Model.from_scene(scene, table_mass=1e6)
    qp = step_qp(get_formulation("velocity"), heavy, State.initial(scene), 0.01)
    assert qp.n_variables == 2 * 4 * (scene.n_boxes + len(scene.tables))
    assert qp.n_equalities == 5 * scene.n_boxes + 2 * 4 * len(scene.tables)
    fixed = simulate(scene, dt=0.01, steps=120, tol="high", formulation="velocity")
    errors, polished = [], []
    for table_mass in (1e2, 1e6):
        held = simulate(scene, dt=0.01, steps=120, tol="high", table_mass=table_mass,
                        polish=False, formulation="velocity")
        errors.append(float(np.abs(held.points - fixed.points).max()))
        held = simulate(scene, dt=0.01, steps=120, tol="high", table_mass=table_mass,
                        formulation="velocity")
        polished.append(float(np.abs(held.points - fixed.points).max()))
    # The held corners have zero velocity either way, so both variants have the same
    # exact minimiser; the heavy weights only worsen the conditioning (M / 0.25 kg), and
    # the solver's error grows with it: the seed's "largest mass" is a numerical hazard.
    assert errors[0] < 1e-7  # m, a light table: as good as a fixed one
    assert errors[1] > 100 * errors[0]
    # polished on its active set, either answer is the exact minimiser (round-off: 1e-13 m
    # measured on positions of order 1 m over 120 steps)
    assert max(polished) < 1e-12


def test_quarter_overlap_is_pushed_apart_not_merged() -> None:
    # overlap-recovery starts with the upper unit square 25 % into the lower one.  Held
    # along one normal per pair, it is pushed up and out and comes to rest on top.  (With
    # the per-corner edge rule the sunk corners were pushed out sideways through the side
    # faces: the squares slid into each other and ended coincident, while the deepest
    # point-to-nearest-face depth read 0.)
    traj = simulate("overlap-recovery", dt=0.01, steps=200)
    corners = traj.points.reshape(len(traj.points), -1, 4, 2)
    assert polygon_overlap_depth(corners[0, 0], corners[0, 1]) == pytest.approx(0.25)
    assert polygon_overlap_depth(corners[-1, 0], corners[-1, 1]) < 1e-6
    centers = corners[-1].mean(axis=1)
    assert centers[1, 1] - centers[0, 1] == pytest.approx(1.0, abs=1e-6)  # resting on top


@pytest.mark.parametrize("solver", ["CLARABEL", "PIQP", "OSQP"])
def test_aligned_stack_stays_put_with_its_duplicate_rows(solver: str) -> None:
    # Each interface of stack-10 holds 4 rows, 2 pairs of coincident corners (see
    # test_contacts_manifold); the duplicates leave the stack at rest to 1e-9 m at tol
    # default over 3 s (measured: 1.1e-10 m at most).
    traj = simulate("stack-10", dt=0.01, steps=300, solver=solver)
    assert traj.metrics["verified"].all()
    assert np.abs(traj.points - traj.points[0]).max() < 1e-9
