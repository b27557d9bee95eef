"""The per-pair manifold rule: one contact normal per body pair, corners clipped to faces.

Each test builds a small geometric case and checks which corner is held by which face.
Corners are numbered counter-clockwise from the lower-left one, so for an unrotated body
face 0 is the bottom, 1 the right side, 2 the top and 3 the left side (face ``e`` joins
corners ``e`` and ``e + 1``, and a row's ``edge_j`` is corner ``e``).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from wuerfel_cvx import Scene
from wuerfel_cvx.scenes.geometry import FloatArray, square_corners
from wuerfel_cvx.scenes.scene import Box, Square, Table
from wuerfel_cvx.step.contacts import Contacts, find_contacts
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.unit

MARGIN = 5e-3
"""Search margin (m) per body, so 1 cm per pair: the velocity formulation's resting reach."""


def model_of(*bodies: Square | Box | Table) -> tuple[Model, FloatArray]:
    """A model of the given squares and boxes (in order) and tables, and its corners."""
    boxes = tuple(b for b in bodies if not isinstance(b, Table))
    tables = tuple(b for b in bodies if isinstance(b, Table))
    scene = Scene("case", boxes, tables, allow_overlap=True)
    return Model.from_scene(scene), scene.initial_points()


def held(contacts: Contacts, body: int) -> set[tuple[int, int, int]]:
    """(corner of ``body``, edge body, face) for each row holding a corner of ``body``."""
    mine = contacts.point_body == body
    return set(zip((contacts.point[mine] % 4).tolist(), contacts.edge_body[mine].tolist(),
                   (contacts.edge_j[mine] % 4).tolist(), strict=True))


def pushes(model: Model, points: FloatArray, contacts: Contacts) -> FloatArray:
    """Unit direction ``(rows, 2)`` in which each row pushes its pair's higher-numbered body.

    A row pushes its point along the outward normal of its edge and the edge body the
    other way; the normal of the counter-clockwise edge ``d = p_i - p_j`` is ``(d_y, -d_x)``.
    """
    p = model.all_points(points)
    d = p[contacts.edge_i] - p[contacts.edge_j]
    normal = np.stack([d[:, 1], -d[:, 0]], axis=1) / np.linalg.norm(d, axis=1)[:, None]
    sign = np.where(contacts.point_body > contacts.edge_body, 1.0, -1.0)
    return normal * sign[:, None]


def assert_one_sense_per_pair(model: Model, points: FloatArray, contacts: Contacts) -> int:
    """No two rows of a pair push its bodies apart in directions more than 90 deg apart.

    Every row's direction is within 45 deg of the reference normal (a rectangle's incident
    face is at most 45 deg off it), so any two are within 90 deg.  Returns the pairs seen.
    """
    direction = pushes(model, points, contacts)
    low = np.minimum(contacts.point_body, contacts.edge_body)
    high = np.maximum(contacts.point_body, contacts.edge_body)
    pairs = set(zip(low.tolist(), high.tolist(), strict=True))
    for a, b in pairs:
        rows = direction[(low == a) & (high == b)]
        assert np.min(rows @ rows.T) > -1e-12, (a, b)
    return len(pairs)


@pytest.mark.parametrize("seed", range(8))
def test_random_overlapping_states_push_each_pair_one_way(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 30))
    points = np.concatenate([square_corners(rng.uniform(-2, 2, size=2), rng.uniform(0.3, 1.5),
                                            rng.uniform(-math.pi, math.pi)) for _ in range(n)])
    tables = tuple(Table(center=tuple(rng.uniform(-3, 3, size=2)),
                         size=tuple(rng.uniform(0.5, 6, size=2)), angle=float(rng.uniform(-1, 1)))
                   for _ in range(2))
    model, _ = model_of(*(Square(center=(3.0 * k, 100.0)) for k in range(n)), *tables)
    seen = 0
    for margin in (0.0, 0.05, 0.5):
        seen += assert_one_sense_per_pair(model, points, find_contacts(model, points, margin))
    assert seen > 0


def test_small_box_on_a_big_one_is_held_by_the_big_ones_top_face() -> None:
    # Unit square, and a 0.5 m square resting on it off-centre: its bottom corners on the
    # top face; the big square's top corners lie beyond the small one's bottom face.
    model, points = model_of(Square(center=(0.0, 0.5)), Square(center=(0.1, 1.25), size=0.5))
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 1) == {(0, 0, 2), (1, 0, 2)}
    assert held(contacts, 0) == set()


def test_big_box_on_a_small_one_holds_the_small_ones_top_corners() -> None:
    model, points = model_of(Square(center=(0.0, 0.25), size=0.5), Square(center=(0.1, 1.0)))
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 0) == {(2, 1, 0), (3, 1, 0)}  # on the big square's bottom face
    assert held(contacts, 1) == set()


def test_box_on_a_wider_table_is_held_by_its_bottom_corners() -> None:
    model, points = model_of(Square(center=(0.3, 0.5)), Table(center=(0.0, -0.5),
                                                              size=(4.0, 1.0)))
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 0) == {(0, 1, 2), (1, 1, 2)}
    assert held(contacts, 1) == set()


def test_box_over_a_tables_end_is_held_by_its_corner_and_the_tables_corner() -> None:
    # The table's top face spans x in [-2, 1]; the box's bottom spans [0.7, 1.7].  Its
    # corner beyond the end is below nothing: no row.  The table's end corner (corner 2)
    # holds the box's bottom face instead.
    model, points = model_of(Square(center=(1.2, 0.5)), Table(center=(-0.5, -0.5),
                                                              size=(3.0, 1.0)))
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 0) == {(0, 1, 2)}
    assert held(contacts, 1) == {(2, 0, 0)}


def test_box_tipping_over_a_tables_end_is_held_at_the_tables_corner() -> None:
    # Rotated 0.1 rad clockwise about the table's end corner (1, 0): the overhanging
    # corner is 7 cm below the top face's line, beyond its end, and is not held.
    angle = -0.1
    center = np.array([1.2 - 1.0, 0.5]) @ np.array([[math.cos(angle), math.sin(angle)],
                                                    [-math.sin(angle), math.cos(angle)]])
    model, points = model_of(Square(center=tuple(center + [1.0, 0.0]), angle=angle),
                             Table(center=(-0.5, -0.5), size=(3.0, 1.0)))
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 0) == set()  # corner 0 lifts off; corner 1 is beyond the end
    assert held(contacts, 1) == {(2, 0, 0)}
    assert contacts.distance[contacts.point_body == 1] == pytest.approx(0.0, abs=1e-12)


def test_corner_first_landing_holds_the_lowest_corner_on_the_table() -> None:
    angle = math.radians(30.0)
    half_diagonal = math.sqrt(0.5) * math.cos(math.radians(15.0))  # centre above the corner
    model, points = model_of(Square(center=(0.0, half_diagonal + 1e-3), angle=angle),
                             Table(center=(0.0, -0.5), size=(4.0, 1.0)))
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 0) == {(0, 1, 2)}
    assert held(contacts, 1) == set()
    assert contacts.distance == pytest.approx([1e-3], abs=1e-12)


def test_box_in_a_corner_is_held_by_the_floor_and_the_wall() -> None:
    model, points = model_of(Square(center=(0.5, 0.5)), Table(center=(0.0, -0.5), size=(6, 1)),
                             Table(center=(-0.5, 2.0), size=(1.0, 6.0)))
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 0) == {(0, 1, 2), (1, 1, 2), (0, 2, 1), (3, 2, 1)}
    assert_one_sense_per_pair(model, points, contacts)


def test_quarter_overlap_pushes_sideways_only() -> None:
    # Two unit squares overlapping by 0.25 m along x: every row pushes along x.
    model, points = model_of(Square(center=(0.0, 0.5)), Square(center=(0.75, 0.5)))
    contacts = find_contacts(model, points, MARGIN)
    np.testing.assert_allclose(np.abs(pushes(model, points, contacts)), [[1.0, 0.0]] * 4,
                               atol=1e-15)
    np.testing.assert_allclose(contacts.distance, -0.25, atol=1e-15)
    assert held(contacts, 1) == {(0, 0, 1), (3, 0, 1)}  # the right square's left corners
    assert held(contacts, 0) == {(1, 1, 3), (2, 1, 3)}


def test_fast_drop_with_a_wide_margin_pushes_only_vertically() -> None:
    # 5 cm above a table with a 0.3 m margin per body (a speculative reach far larger than
    # the gap): the box's top corners are offered too and lie beyond the margin, and every
    # row is against the table's top face or the box's bottom face.
    half_height = 0.5 * (math.cos(0.05) + math.sin(0.05))
    model, points = model_of(Square(center=(0.0, half_height + 0.05), angle=0.05),
                             Table(center=(0.0, -0.5), size=(4.0, 1.0)))
    contacts = find_contacts(model, points, 0.3)
    assert held(contacts, 0) == {(0, 1, 2), (1, 1, 2)}
    assert held(contacts, 1) == set()  # the table's corners are 1.5 m past the box's face
    np.testing.assert_allclose(pushes(model, points, contacts), [[0.0, -1.0]] * 2, atol=1e-15)


def test_a_corner_past_a_faces_end_is_offered_within_the_margin_of_the_face() -> None:
    # A unit square 2 cm above a table's end and 1 cm past it: the box's corner 0 is
    # 2.2 cm from the table's top face (the segment), 2 cm from its line, and so is the
    # table's end corner from the box's bottom face.
    model, points = model_of(Square(center=(1.51, 0.52)), Table(center=(-0.5, -0.5),
                                                                size=(3.0, 1.0)))
    near = find_contacts(model, points, 0.012)  # 2.4 cm per pair
    assert held(near, 0) == {(0, 1, 2)}
    assert held(near, 1) == {(2, 0, 0)}
    np.testing.assert_allclose(near.distance, 0.02, atol=1e-12)
    far = find_contacts(model, points, 0.0105)  # 2.1 cm: within reach of the line only
    assert len(far) == 0


def test_corners_approaching_each_other_are_held_before_they_meet() -> None:
    # Two squares rotated 45 and 40 degrees, corner towards corner, 3 cm apart: no corner
    # lies within the other's faces' extent, yet the pair gets a row along one normal.
    r = math.sqrt(0.5)
    model, points = model_of(Square(center=(0.0, 0.0), angle=math.radians(45.0)),
                             Square(center=(2.0 * r + 0.03, 0.0), angle=math.radians(40.0)))
    contacts = find_contacts(model, points, 0.05)
    assert len(contacts) >= 1
    assert np.all(contacts.distance > 0.0)
    assert_one_sense_per_pair(model, points, contacts)


def test_aligned_stack_holds_each_coincident_corner_pair_twice_in_one_sense() -> None:
    # Equal aligned squares: each lower top corner coincides with an upper bottom corner,
    # and both are within the other's face (at its end).  The two rows of such a pair are
    # the same constraint on the two bodies' rigid motion, pushing the same way.
    scene = Scene.named("stack-3")
    model = Model.from_scene(scene)
    points = scene.initial_points()
    contacts = find_contacts(model, points, MARGIN)
    assert held(contacts, 1) == {(0, 0, 2), (1, 0, 2), (2, 2, 0), (3, 2, 0)}
    between = (np.minimum(contacts.point_body, contacts.edge_body) == 0) & (
        np.maximum(contacts.point_body, contacts.edge_body) == 1)
    assert np.count_nonzero(between) == 4
    np.testing.assert_allclose(pushes(model, points, contacts)[between], [[0.0, 1.0]] * 4,
                               atol=1e-15)


def test_a_tie_goes_to_the_longer_face_so_no_row_reaches_far_past_a_tiny_face() -> None:
    # A 1 mm square resting on a 4 m table, searched with a 5 m margin per body (a fast
    # body's reach).  Both faces separate by 0: the table's top face holds the square's
    # corners, and the table's corners, 2 m past the square's 1 mm face, are not held by
    # that face's line (a row with a lever arm of 2000 face lengths).
    model, points = model_of(Square(center=(0.0, 5e-4), size=1e-3),
                             Table(center=(0.0, -0.5), size=(4.0, 1.0)))
    contacts = find_contacts(model, points, 5.0)
    assert held(contacts, 1) == set()
    assert held(contacts, 0) == {(k, 1, 2) for k in range(4)}  # the top corners too, at 1 mm
