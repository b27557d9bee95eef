"""The field's benchmark scenes (:mod:`wuerfel_cvx.scenes.library`) and their example files.

Counts, friction coefficients and positions are checked against the numbers of the
Solver2D and Box2D sources the module docstring names; overlaps with the metrics'
separating-axis depth and, for the smaller scenes, pair by pair.
"""

from __future__ import annotations

import itertools
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from wuerfel_cvx import InputError, Scene, simulate
from wuerfel_cvx.scenes.geometry import polygon_overlap_depth, polygon_overlap_depths
from wuerfel_cvx.scenes.library import (
    DOUBLE_DOMINO_IMPULSE,
    EXAMPLE_NAMES,
    FIELD_SCENES,
    example_text,
    scene_names,
    write_examples,
)
from wuerfel_cvx.scenes.scene import DEFAULT_GRAVITY, OVERLAP_TOLERANCE, Square, Table
from wuerfel_cvx.step.metrics import deepest_overlap
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.unit

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"

#: Moving bodies of each field scene, as the sources build them.
BODY_COUNTS = {
    "vertical-stack": 15, "field-pyramid-10": 55, "field-pyramid-20": 210,
    "field-pyramid": 55, "large-pyramid": 5050, "friction-ramps": 5,
    "high-mass-ratio-1": 3 * 55, "high-mass-ratio-2": 3, "overlap-recovery-friction": 10,
    "card-house": 40, "double-domino": 15, "tilted-stack": 100,
}

#: Friction of the moving bodies and of the tables of each field scene.
FRICTION = {
    "vertical-stack": (0.3, 0.6), "field-pyramid-10": (0.6, 0.6),
    "field-pyramid-20": (0.6, 0.6), "large-pyramid": (0.6, 0.6),
    "high-mass-ratio-1": (0.5, 0.5), "high-mass-ratio-2": (0.6, 0.6),
    "overlap-recovery-friction": (0.6, 0.6), "card-house": (0.7, 0.7),
    "double-domino": (0.6, 0.6), "tilted-stack": (0.3, 0.6),
}

OVERLAPPING = "overlap-recovery-friction"


def centres(scene: Scene) -> np.ndarray:
    """Centres ``(n, 2)`` (m) of a scene's moving bodies."""
    return np.array([body.center for body in scene.bodies])


@pytest.mark.parametrize(("name", "count"), BODY_COUNTS.items())
def test_each_field_scene_builds_with_the_sources_body_count(name: str, count: int) -> None:
    scene = Scene.named(name)
    assert scene.n_boxes == count
    assert scene.gravity == DEFAULT_GRAVITY
    assert scene.name == ("field-pyramid-10" if name == "field-pyramid" else name)
    assert Scene.from_dict(scene.to_dict()) == scene


def test_every_field_scene_is_in_the_library() -> None:
    listed = scene_names()
    assert all(pattern in listed for pattern, *_ in FIELD_SCENES)
    assert {pattern.replace("-N", "-10") for pattern, *_ in FIELD_SCENES} <= set(BODY_COUNTS)


@pytest.mark.parametrize("name", sorted(set(BODY_COUNTS) - {OVERLAPPING}))
def test_no_two_bodies_start_overlapped(name: str) -> None:
    scene = Scene.named(name)
    assert not scene.allow_overlap
    assert deepest_overlap(Model.from_scene(scene), scene.initial_points()) <= OVERLAP_TOLERANCE
    if scene.n_boxes <= 120:  # and pair by pair, boxes and tables included
        shapes = [body.corners() for body in scene.bodies]
        tables = [table.corners() for table in scene.tables]
        for a, b in itertools.combinations(shapes, 2):
            assert polygon_overlap_depth(a, b) <= OVERLAP_TOLERANCE
        for a, b in itertools.product(shapes, tables):
            assert polygon_overlap_depth(a, b) <= OVERLAP_TOLERANCE


def test_overlap_recovery_friction_starts_a_quarter_side_overlapped() -> None:
    scene = Scene.named(OVERLAPPING)
    assert scene.allow_overlap
    assert deepest_overlap(Model.from_scene(scene), scene.initial_points()) == pytest.approx(
        0.25, abs=1e-12)
    rows = sorted({body.center[1] for body in scene.bodies})
    assert rows == pytest.approx([0.5, 1.25, 2.0, 2.75], abs=1e-12)  # 0.75 m apart: 1 m sides
    ground = scene.tables[0].corners()
    assert max(polygon_overlap_depth(b.corners(), ground) for b in scene.bodies) == 0.0
    with pytest.raises(InputError, match="by 0.25 m"):
        Scene(scene.name, scene.squares, scene.tables)


@pytest.mark.parametrize(("name", "mu"), FRICTION.items())
def test_friction_is_the_sources(name: str, mu: tuple[float, float]) -> None:
    scene = Scene.named(name)
    assert {body.friction for body in scene.bodies} == {mu[0]}
    assert {table.friction for table in scene.tables} == {mu[1]}


def test_friction_ramps_are_the_sources() -> None:
    scene = Scene.named("friction-ramps")
    assert [box.friction for box in scene.squares] == [0.75, 0.5, 0.35, 0.1, 0.0]
    assert {table.friction for table in scene.tables} == {0.2}
    assert all(box.mass == 25.0 and box.size == 1.0 for box in scene.squares)
    ramps = [t for t in scene.tables if t.size == (26.0, 0.5)]
    assert [t.angle for t in ramps] == [-0.25, 0.25, -0.25]
    top = max(ramps, key=lambda t: t.center[1])
    for box in scene.squares:  # each box falls onto the top ramp
        along = (box.center[0] - top.center[0]) / math.cos(top.angle)
        assert abs(along) < top.size[0] / 2
        surface = top.center[1] + along * math.sin(top.angle) + 0.25 / math.cos(top.angle)
        assert box.center[1] - 0.5 > surface


@pytest.mark.parametrize("base", [1, 2, 10, 20])
def test_field_pyramid_rows_touch_and_step_in_by_half_a_side(base: int) -> None:
    scene = Scene.named(f"field-pyramid-{base}")
    assert scene.n_boxes == base * (base + 1) // 2
    xy = centres(scene)
    for row in range(base):
        in_row = xy[np.isclose(xy[:, 1], row + 0.5)]
        assert len(in_row) == base - row
        np.testing.assert_allclose(np.diff(np.sort(in_row[:, 0])), 1.0, atol=1e-12)
        assert float(in_row[:, 0].min()) == pytest.approx(-base / 2 + 0.5 + row / 2, abs=1e-12)
    assert float(np.max(scene.tables[0].corners()[:, 1])) == 0.0
    assert float(np.min(scene.initial_points()[:, 1])) == 0.0


def test_large_pyramid_is_the_base_100_field_pyramid() -> None:
    large, family = Scene.named("large-pyramid"), Scene.named("field-pyramid-100")
    assert large.bodies == family.bodies and large.tables == family.tables


def test_vertical_stack_offsets_and_gaps() -> None:
    xy = centres(Scene.named("vertical-stack"))
    np.testing.assert_array_equal(xy[:, 0], [(-0.01, 0.01)[i % 2] for i in range(15)])
    np.testing.assert_allclose(np.diff(xy[:, 1]), 1.1, atol=1e-12)
    assert xy[0, 1] == 0.55


def test_tilted_stack_columns_lean_by_a_fifth_of_a_side_a_row() -> None:
    xy = centres(Scene.named("tilted-stack")).reshape(10, 10, 2)
    np.testing.assert_allclose(np.diff(xy[:, :, 0], axis=1), 0.2, atol=1e-12)
    np.testing.assert_allclose(np.diff(xy[:, 0, 0]), 5.0, atol=1e-12)
    np.testing.assert_array_equal(xy[0, :, 1], 0.5 + np.arange(10))


def test_high_mass_ratio_1_has_heavy_tops_dropped_from_two_metres() -> None:
    scene = Scene.named("high-mass-ratio-1")
    masses = np.array([body.mass for body in scene.bodies]).reshape(3, 55)
    np.testing.assert_array_equal(masses[:, :-1], 4.0)  # 2 m boxes of density 1
    np.testing.assert_array_equal(masses[:, -1], [400.0, 800.0, 1200.0])
    xy = centres(scene).reshape(3, 55, 2)
    np.testing.assert_allclose(xy[:, -1, 1] - xy[:, -2, 1], 4.0)  # 2 m + one 2 m row
    np.testing.assert_allclose(xy[:, -1, 0], (xy[:, -2, 0] + xy[:, -3, 0]) / 2)


def test_high_mass_ratio_2_drops_400_kg_onto_two_1_kg_boxes() -> None:
    small_left, small_right, big = Scene.named("high-mass-ratio-2").squares
    assert (small_left.mass, small_right.mass, big.mass) == (1.0, 1.0, 400.0)
    assert big.size == 20.0 and big.center[1] - big.size / 2 == 16.0
    assert small_left.center == (-9.0, 0.5) and small_right.center == (9.0, 0.5)


def test_card_house_stands_on_the_ground_in_five_floors() -> None:
    scene = Scene.named("card-house")
    cards = scene.boxes
    tilts = sorted({round(math.degrees(card.angle), 9) for card in cards})
    assert tilts == [-25.0, 25.0, 90.0]
    assert sum(card.angle == 0.5 * math.pi for card in cards) == 4 + 3 + 2 + 1
    assert float(np.min(scene.initial_points()[:, 1])) == pytest.approx(0.0, abs=1e-15)
    assert float(np.max(scene.tables[0].corners()[:, 1])) == 0.0
    floors = sorted({round(card.center[1], 9) for card in cards if card.angle != 0.5 * math.pi})
    assert len(floors) == 5


def test_double_domino_first_domino_carries_boxes_impulse() -> None:
    dominoes = Scene.named("double-domino").boxes
    first = dominoes[0]
    assert np.all(np.diff([d.center[0] for d in dominoes]) == 1.0)
    # the impulse J at the middle of the top face: m v = J and I omega = r x J, with I of
    # the 4 corner masses summed from the corners
    corners = first.corners() - np.asarray(first.center)
    inertia = first.mass / 4 * float(np.sum(corners ** 2))
    r = (0.0, first.height / 2)
    np.testing.assert_allclose(np.multiply(first.velocity, first.mass), DOUBLE_DOMINO_IMPULSE)
    torque = r[0] * DOUBLE_DOMINO_IMPULSE[1] - r[1] * DOUBLE_DOMINO_IMPULSE[0]
    assert first.angular_velocity * inertia == pytest.approx(torque, rel=1e-12)
    assert all(d.velocity == (0.0, 0.0) and d.angular_velocity == 0.0 for d in dominoes[1:])


# ------------------------------------------------------------------ the example files
@pytest.mark.parametrize("name", EXAMPLE_NAMES)
def test_example_file_is_the_writers_and_loads_to_the_library_scene(name: str) -> None:
    path = EXAMPLES / f"{name}.toml"
    assert path.read_text(encoding="utf-8") == example_text(name)
    assert Scene.from_toml(path) == Scene.named(name)


def test_examples_cover_every_field_scene_but_the_large_pyramid() -> None:
    patterns = {pattern for pattern, *_ in FIELD_SCENES}
    named = {name if name in patterns else "field-pyramid-N" for name in EXAMPLE_NAMES}
    assert named == patterns - {"large-pyramid"}
    assert not (EXAMPLES / "large-pyramid.toml").exists()


def test_write_examples_writes_each_file(tmp_path: Path) -> None:
    paths = write_examples(tmp_path)
    assert [p.name for p in paths] == [f"{name}.toml" for name in EXAMPLE_NAMES]
    for path in paths:
        assert path.read_bytes() == (EXAMPLES / path.name).read_bytes()


@pytest.mark.parametrize("name", [n.replace("-N", "-3") for n in scene_names()])
def test_to_toml_parses_to_to_dict(name: str) -> None:
    scene = Scene.named(name)
    assert tomllib.loads(scene.to_toml()) == scene.to_dict()


def test_to_toml_escapes_names_and_keeps_every_digit() -> None:
    square = Square(center=(0.1 + 0.2, 1.0 + 1.0 / 3.0), angle=-1e-17, mass=1e-6, friction=0.3)
    scene = Scene('W\u00fcrfel "3" \\ \u007f\t\U0001f9ca', (square,),
                  (Table(center=(0.0, -0.5)),))
    assert Scene.from_dict(tomllib.loads(scene.to_toml())) == scene


# ------------------------------------------------------------------ the batched overlap test
def test_batched_overlap_depths_match_the_pairwise_test() -> None:
    rng = np.random.default_rng(13)
    first = np.array([Square(center=tuple(rng.uniform(-1, 1, 2)), size=rng.uniform(0.2, 2),
                             angle=rng.uniform(-3, 3)).corners() for _ in range(300)])
    second = np.array([Square(center=tuple(rng.uniform(-1, 1, 2)), size=rng.uniform(0.2, 2),
                              angle=rng.uniform(-3, 3)).corners() for _ in range(300)])
    batched = polygon_overlap_depths(first, second)
    pairwise = [polygon_overlap_depth(a, b) for a, b in zip(first, second, strict=True)]
    assert 0 < np.count_nonzero(batched) < 300  # overlapping pairs and separate ones
    np.testing.assert_allclose(batched, pairwise, rtol=0, atol=1e-13)
    assert polygon_overlap_depths(np.zeros((0, 4, 2)), np.zeros((0, 4, 2))).shape == (0,)


@pytest.mark.parametrize(("depth", "rejected"), [(0.9 * OVERLAP_TOLERANCE, False),
                                                 (1.1 * OVERLAP_TOLERANCE, True)])
def test_loader_rejects_an_overlap_just_beyond_its_tolerance(depth: float,
                                                             rejected: bool) -> None:
    squares = (Square(center=(0.0, 0.5)), Square(center=(1.0 - depth, 0.5)))
    floor = (Table(center=(0.0, -0.5)),)
    if rejected:
        with pytest.raises(InputError, match="overlaps squares\\[1\\]"):
            Scene("near", squares, floor)
    else:
        assert Scene("near", squares, floor).n_boxes == 2


# ------------------------------------------------------------------ smoke runs
@pytest.mark.integration
@pytest.mark.parametrize("name", ["high-mass-ratio-2", "friction-ramps"])
def test_small_field_scenes_run(name: str) -> None:
    # friction is not in the QP on its own yet: these bodies fall freely or rest
    scene = Scene.named(name)
    dt, steps = 1.0 / 60.0, 3
    trajectory = simulate(scene, dt=dt, steps=steps)
    assert trajectory.n_steps == steps
    assert np.all(np.isfinite(trajectory.points)) and np.all(np.isfinite(trajectory.velocities))
    velocity = trajectory.velocities[-1].reshape(-1, 4, 2).mean(axis=1)
    assert not scene.boxes  # squares only, unrotated: the lowest point is half a side down
    falling = np.array([body.center[1] - body.size / 2 > 1.0 for body in scene.squares])
    fall = steps * dt * DEFAULT_GRAVITY[1]  # free fall, g t (m/s)
    np.testing.assert_allclose(velocity[falling, 1], fall, rtol=1e-9)
    if (~falling).any():  # resting on the ground: held there, to far below one g dt
        assert float(np.min(trajectory.points[-1][:, 1])) >= -OVERLAP_TOLERANCE
        assert float(np.max(np.abs(velocity[~falling]))) < 1e-6 * abs(fall)
