"""Tests of scene loading (:mod:`wuerfel_cvx.scenes.scene`) and the named-scene library.

Covers the TOML schema (the example file, defaults, the ``to_dict``/``from_dict``
round trip), the corner arrays a scene hands to the simulator, every way a scene
file can be wrong (each must raise :class:`~wuerfel_cvx.errors.InputError` naming
the file and the dotted field), and the scenes of :mod:`wuerfel_cvx.scenes.library`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from wuerfel_cvx.errors import InputError
from wuerfel_cvx.scenes.geometry import FloatArray, polygon_overlap_depth, square_corners
from wuerfel_cvx.scenes.library import FLOOR, scene_names
from wuerfel_cvx.scenes.scene import DEFAULT_GRAVITY, OVERLAP_TOLERANCE, Scene, Square, Table
from wuerfel_cvx.step.metrics import deepest_overlap
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.unit

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "tilted-drop.toml"

#: A family number small enough to keep the library tests fast.
SMALL_N = 3
#: Squares beyond which a scene's pairs are found by a k-d tree, not all tested.
EXHAUSTIVE_PAIRS_LIMIT = 120


def shoelace_area(polygon: FloatArray) -> float:
    """Signed area (m^2) of a polygon; positive when its corners run counter-clockwise."""
    x, y = polygon[:, 0], polygon[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def write_scene(tmp_path: Path, text: str | bytes, name: str = "scene.toml") -> Path:
    """Write ``text`` (str as UTF-8, bytes verbatim) to ``tmp_path / name``."""
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------ the example file
def test_example_file_loads_with_the_values_it_states() -> None:
    scene = Scene.from_toml(EXAMPLE)
    assert scene.name == "tilted-drop"
    assert scene.gravity == (0.0, -9.81)
    assert scene.allow_overlap is False
    assert scene.source == str(EXAMPLE)
    assert scene.tables == (Table(center=(0.0, -0.5), size=(20.0, 1.0), angle=0.0),)
    assert scene.squares == (
        Square(center=(0.0, 2.0), size=1.0, angle=0.3, mass=1.0, velocity=(0.0, 0.0),
               angular_velocity=0.0),
    )
    assert scene.n_boxes == 1


def test_example_file_states_every_key_of_the_schema() -> None:
    data = tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))
    assert set(data) == {"name", "gravity", "allow_overlap", "tables", "squares"}
    assert set(data["tables"][0]) == {"center", "size", "angle"}
    assert set(data["squares"][0]) == {"center", "size", "angle", "mass", "velocity",
                                       "angular_velocity"}


def test_omitted_keys_take_their_defaults(tmp_path: Path) -> None:
    path = write_scene(tmp_path, "[[tables]]\ncenter = [1.0, -3.0]\n\n"
                                 "[[squares]]\ncenter = [0.5, 2]\n", name="my-drop.toml")
    scene = Scene.from_toml(path)
    assert scene.name == "my-drop"  # the file's stem
    assert scene.gravity == DEFAULT_GRAVITY == (0.0, -9.81)
    assert scene.allow_overlap is False
    assert scene.tables == (Table(center=(1.0, -3.0), size=(20.0, 1.0), angle=0.0),)
    (square,) = scene.squares
    assert square.center == (0.5, 2.0)
    assert isinstance(square.center[1], float)  # TOML integers become floats
    assert (square.size, square.angle, square.mass) == (1.0, 0.0, 1.0)
    assert square.velocity == (0.0, 0.0)
    assert square.angular_velocity == 0.0


def test_tables_are_optional(tmp_path: Path) -> None:
    scene = Scene.from_toml(write_scene(tmp_path, "[[squares]]\ncenter = [0, 0]\n"))
    assert scene.tables == ()
    assert scene.table_points().shape == (0, 2)


def test_from_dict_without_a_toml_source_names_the_scene_scene() -> None:
    assert Scene.from_dict({"squares": [{"center": [0, 0]}]}).name == "scene"


def test_to_dict_round_trips_through_from_dict() -> None:
    scene = Scene.from_toml(EXAMPLE)
    data = scene.to_dict()
    assert data == {
        "name": "tilted-drop",
        "gravity": [0.0, -9.81],
        "allow_overlap": False,
        "tables": [{"center": [0.0, -0.5], "size": [20.0, 1.0], "angle": 0.0}],
        "squares": [{"center": [0.0, 2.0], "size": 1.0, "angle": 0.3, "mass": 1.0,
                     "velocity": [0.0, 0.0], "angular_velocity": 0.0}],
    }
    again = Scene.from_dict(data)
    assert again == scene
    assert again.to_dict() == data


def test_to_dict_round_trips_non_default_values() -> None:
    scene = Scene(
        "varied",
        (Square(center=(-3.0, 4.0), size=0.5, angle=-1.2, mass=2.5, velocity=(1.0, -2.0),
                angular_velocity=7.0),
         Square(center=(3.0, 1.0), size=2.0, angle=0.7)),
        (Table(center=(0.0, -1.0), size=(8.0, 2.0), angle=0.05),),
        gravity=(1.0, -3.0),
        allow_overlap=True,
    )
    again = Scene.from_dict(scene.to_dict())
    assert again == scene
    assert again.squares[0].angular_velocity == 7.0
    assert again.tables[0].angle == 0.05
    assert again.allow_overlap is True


# ------------------------------------------------------------------ corner arrays
def _three_squares() -> Scene:
    return Scene(
        "three",
        (Square(center=(0.0, 1.0), size=1.0, angle=0.0, velocity=(2.0, 0.0)),
         Square(center=(5.0, 2.0), size=0.5, angle=0.4, velocity=(0.0, -1.0),
                angular_velocity=3.0),
         Square(center=(-4.0, 3.0), size=2.0, angle=2.5, velocity=(1.0, 1.5),
                angular_velocity=-1.7)),
        (Table(center=(0.0, -1.0), size=(30.0, 2.0), angle=0.0),),
    )


def test_initial_points_are_counter_clockwise_corners_of_each_square() -> None:
    scene = _three_squares()
    points = scene.initial_points()
    assert points.shape == (4 * scene.n_boxes, 2)
    for i, square in enumerate(scene.squares):
        corners = points[4 * i:4 * i + 4]
        assert shoelace_area(corners) == pytest.approx(square.size**2, rel=1e-12)
        np.testing.assert_allclose(corners.mean(axis=0), square.center, atol=1e-12)
        edges = np.roll(corners, -1, axis=0) - corners
        np.testing.assert_allclose(np.linalg.norm(edges, axis=1), square.size, rtol=1e-12)
        # The first edge points along the square's rotated x axis.
        np.testing.assert_allclose(edges[0] / square.size,
                                   [math.cos(square.angle), math.sin(square.angle)],
                                   atol=1e-12)


def test_axis_aligned_unit_square_corners_start_lower_left() -> None:
    scene = Scene("one", (Square(center=(1.0, 2.0)),))
    np.testing.assert_allclose(scene.initial_points(),
                               [[0.5, 1.5], [1.5, 1.5], [1.5, 2.5], [0.5, 2.5]])


def test_table_points_are_counter_clockwise_with_area_width_times_height() -> None:
    scene = Scene("tables", (Square(center=(0.0, 5.0)),),
                  (Table(center=(0.0, -0.5), size=(20.0, 1.0)),
                   Table(center=(30.0, 0.0), size=(3.0, 2.0), angle=0.6)))
    points = scene.table_points()
    assert points.shape == (8, 2)
    assert shoelace_area(points[:4]) == pytest.approx(20.0)
    assert shoelace_area(points[4:]) == pytest.approx(6.0)
    np.testing.assert_allclose(points[4:].mean(axis=0), [30.0, 0.0], atol=1e-12)


def test_initial_velocities_are_v_plus_omega_cross_r() -> None:
    scene = _three_squares()
    velocities = scene.initial_velocities()
    assert velocities.shape == (4 * scene.n_boxes, 2)
    h = 1e-6
    for i, s in enumerate(scene.squares):
        # Central difference of the corners along the rigid motion.
        ahead = square_corners(np.add(s.center, h * np.asarray(s.velocity)), s.size,
                               s.angle + h * s.angular_velocity)
        behind = square_corners(np.subtract(s.center, h * np.asarray(s.velocity)), s.size,
                                s.angle - h * s.angular_velocity)
        np.testing.assert_allclose(velocities[4 * i:4 * i + 4], (ahead - behind) / (2 * h),
                                   rtol=1e-7, atol=1e-7)
        # And the closed form v + omega x r, with omega x r = omega * (-r_y, r_x).
        r = s.corners() - np.asarray(s.center)
        expected = np.asarray(s.velocity) + s.angular_velocity * np.stack(
            [-r[:, 1], r[:, 0]], axis=1)
        np.testing.assert_allclose(velocities[4 * i:4 * i + 4], expected, atol=1e-12)


def test_spinning_square_corner_speeds_differ_from_centre_speed() -> None:
    square = Square(center=(0.0, 0.0), velocity=(0.0, 0.0), angular_velocity=2.0)
    speeds = np.linalg.norm(square.corner_velocities(), axis=1)
    # |omega| times the half diagonal.
    np.testing.assert_allclose(speeds, 2.0 * math.sqrt(0.5), rtol=1e-12)


# ------------------------------------------------------------------ bad input
_SQ = "[[squares]]\ncenter = [0.0, 2.0]\n"
_TB = "[[tables]]\ncenter = [0.0, -0.5]\n"

#: (case id, file content (None: no file), expected field substring or None,
#:  expected substring of the message).
BAD_INPUT: list[tuple[str, str | bytes | None, str | None, str]] = [
    ("missing-file", None, None, "file not found"),
    ("malformed-toml", "[[squares]\ncenter = [0, 2]\n", None, "malformed TOML"),
    ("malformed-value", "[[squares]]\ncenter = [0, 2\n", None, "malformed TOML"),
    ("not-utf8", b"name = \"caf\xe9\"\n" + _SQ.encode(), None, "not UTF-8"),
    ("unknown-top-level-key", "colour = 'red'\n" + _SQ, "colour", "unknown key 'colour'"),
    ("unknown-square-key", _SQ + "spin = 1.0\n", "squares[0].spin", "unknown key 'spin'"),
    ("unknown-table-key", _TB + "restitution = 0.5\n" + _SQ, "tables[0].restitution",
     "unknown key 'restitution'"),
    ("unknown-key-second-square", _SQ + "[[squares]]\ncenter = [5, 2]\nmas = 2\n",
     "squares[1].mas", "unknown key 'mas'"),
    ("missing-square-center", "[[squares]]\nsize = 1.0\n", "squares[0].center",
     "missing required key 'center'"),
    ("missing-table-center", "[[tables]]\nsize = [1.0, 1.0]\n" + _SQ, "tables[0].center",
     "missing required key 'center'"),
    ("zero-mass", _SQ + "mass = 0.0\n", "squares[0].mass", "positive"),
    ("negative-mass", _SQ + "mass = -1\n", "squares[0].mass", "positive"),
    ("zero-size", _SQ + "size = 0\n", "squares[0].size", "positive"),
    ("negative-size", _SQ + "size = -0.5\n", "squares[0].size", "positive"),
    ("zero-table-width", "[[tables]]\ncenter = [0, -5]\nsize = [0.0, 1.0]\n" + _SQ,
     "tables[0].size[0]", "positive"),
    ("negative-table-height", "[[tables]]\ncenter = [0, -5]\nsize = [1.0, -2.0]\n" + _SQ,
     "tables[0].size[1]", "positive"),
    ("nan-mass", _SQ + "mass = nan\n", "squares[0].mass", "finite"),
    ("inf-size", _SQ + "size = inf\n", "squares[0].size", "finite"),
    ("minus-inf-angle", _SQ + "angle = -inf\n", "squares[0].angle", "finite"),
    ("nan-center", "[[squares]]\ncenter = [nan, 2.0]\n", "squares[0].center[0]", "finite"),
    ("inf-velocity", _SQ + "velocity = [0.0, inf]\n", "squares[0].velocity[1]", "finite"),
    ("nan-angular-velocity", _SQ + "angular_velocity = nan\n", "squares[0].angular_velocity",
     "finite"),
    ("inf-gravity", "gravity = [0.0, -inf]\n" + _SQ, "gravity[1]", "finite"),
    ("nan-table-angle", _TB + "angle = nan\n" + _SQ, "tables[0].angle", "finite"),
    ("string-mass", _SQ + "mass = \"1.0\"\n", "squares[0].mass", "expected a number"),
    ("bool-size", _SQ + "size = true\n", "squares[0].size", "expected a number"),
    ("three-element-center", "[[squares]]\ncenter = [0.0, 2.0, 0.0]\n", "squares[0].center",
     "two numbers"),
    ("scalar-velocity", _SQ + "velocity = 3.0\n", "squares[0].velocity", "two numbers"),
    ("string-in-table-size", "[[tables]]\ncenter = [0, -5]\nsize = [1.0, \"2\"]\n" + _SQ,
     "tables[0].size[1]", "expected a number"),
    ("bool-allow-overlap", "allow_overlap = 1\n" + _SQ, "allow_overlap", "true or false"),
    ("empty-name", "name = \"\"\n" + _SQ, "name", "non-empty string"),
    ("squares-not-array", "squares = 3\n", "squares", "array of tables"),
    ("square-not-table", "squares = [1.0]\n", "squares[0]", "expected a table"),
    ("no-squares", "name = \"empty\"\n", "squares", "at least one square or box"),
    ("several-unknown-keys", _SQ + "sise = 1.0\ncolour = 'red'\n", "squares[0]",
     "unknown keys 'colour', 'sise' (allowed: angle, angular_velocity, center, friction, "
     "mass, size, velocity)"),
    ("several-unknown-top-level-keys", "colour = 'red'\nfriction = 0.5\n" + _SQ, None,
     "unknown keys 'colour', 'friction' (allowed: allow_overlap, boxes, gravity, name, "
     "squares, tables)"),
    ("box-in-squares", "[[squares]]\ncenter = [0, 2]\nsize = [2.0, 0.5]\n", "squares[0].size",
     "expected a number, got list"),
    ("squares-overlap", _SQ + "[[squares]]\ncenter = [0.5, 2.5]\n", "squares[0]",
     "overlaps squares[1]"),
    ("third-square-overlaps-second",
     _SQ + "[[squares]]\ncenter = [5.0, 2.0]\n[[squares]]\ncenter = [5.0, 2.9]\nangle = 0.2\n",
     "squares[1]", "overlaps squares[2]"),
    ("square-overlaps-table", _TB + "[[squares]]\ncenter = [0.0, 0.3]\n", "squares[0]",
     "overlaps tables[0]"),
    ("tilted-square-pokes-into-table", _TB + "[[squares]]\ncenter = [3.0, 0.6]\nangle = 0.785\n",
     "squares[0]", "overlaps tables[0]"),
]


@pytest.mark.parametrize(
    ("content", "field", "message"),
    [pytest.param(content, field, message, id=case)
     for case, content, field, message in BAD_INPUT],
)
def test_bad_input_raises_input_error_naming_file_and_field(
    tmp_path: Path, content: str | bytes | None, field: str | None, message: str
) -> None:
    path = tmp_path / "bad-scene.toml"
    if content is not None:
        write_scene(tmp_path, content, name=path.name)
    with pytest.raises(InputError) as info:
        Scene.from_toml(path)
    error = info.value
    text = str(error)
    assert error.source == str(path)
    assert text.startswith(str(path))
    assert message in text
    if field is None:
        assert error.field is None
    else:
        assert error.field is not None
        assert field in error.field
        assert field in text
    assert isinstance(error, ValueError)  # InputError is also a ValueError


def test_several_unknown_keys_are_all_named_on_one_line_with_printable_quoting(
        tmp_path: Path) -> None:
    path = write_scene(tmp_path, _SQ + '"\u202eevil" = 1\n"" = 2\nzz = 3\n')
    with pytest.raises(InputError) as info:
        Scene.from_toml(path)
    assert info.value.field == "squares[0]"
    # sorted as written; bare keys in single quotes, the others escaped in double quotes
    assert info.value.reason == ('unknown keys "", \'zz\', "\\u202eevil" (allowed: angle, '
                                 "angular_velocity, center, friction, mass, size, velocity)")
    assert "\n" not in str(info.value) and "\u202e" not in str(info.value)


def test_overlap_error_message_mentions_overlap_and_allow_overlap(tmp_path: Path) -> None:
    path = write_scene(tmp_path, _SQ + "[[squares]]\ncenter = [0.5, 2.5]\n")
    with pytest.raises(InputError, match=r"overlaps squares\[1\] by 0\.5 m") as info:
        Scene.from_toml(path)
    assert info.value.field == "squares[0]"
    assert "allow_overlap = true" in str(info.value)


def test_allow_overlap_accepts_overlapping_squares(tmp_path: Path) -> None:
    text = "allow_overlap = true\n" + _SQ + "[[squares]]\ncenter = [0.5, 2.5]\n"
    scene = Scene.from_toml(write_scene(tmp_path, text))
    assert scene.allow_overlap is True
    assert scene.n_boxes == 2
    depth = polygon_overlap_depth(scene.squares[0].corners(), scene.squares[1].corners())
    assert depth == pytest.approx(0.5)


def test_allow_overlap_accepts_square_in_table(tmp_path: Path) -> None:
    text = "allow_overlap = true\n" + _TB + "[[squares]]\ncenter = [0.0, 0.3]\n"
    scene = Scene.from_toml(write_scene(tmp_path, text))
    assert polygon_overlap_depth(scene.squares[0].corners(), scene.tables[0].corners()) == (
        pytest.approx(0.2))


def test_touching_squares_are_not_an_overlap(tmp_path: Path) -> None:
    text = _TB + "[[squares]]\ncenter = [0.0, 0.5]\n[[squares]]\ncenter = [0.3, 1.5]\n" \
        "[[squares]]\ncenter = [1.3, 1.5]\n"
    scene = Scene.from_toml(write_scene(tmp_path, text))
    assert scene.n_boxes == 3


def test_overlap_just_above_tolerance_is_rejected() -> None:
    gap = 10 * OVERLAP_TOLERANCE
    with pytest.raises(InputError, match="overlaps"):
        Scene("close", (Square(center=(0.0, 0.5)), Square(center=(0.0, 1.5 - gap))))
    Scene("close", (Square(center=(0.0, 0.5)), Square(center=(0.0, 1.5 + gap))))


def test_constructor_checks_values_like_the_loader() -> None:
    with pytest.raises(InputError) as info:
        Scene("code", (Square(center=(0.0, 2.0)), Square(center=(5.0, 2.0), mass=-1.0)))
    assert info.value.field == "squares[1].mass"
    with pytest.raises(InputError) as info:
        Scene("code", (Square(center=(0.0, 2.0), size=math.nan),))
    assert info.value.field == "squares[0].size"
    with pytest.raises(InputError) as info:
        Scene("code", (Square(center=(0.0, 2.0)),), gravity=(0.0, math.inf))
    assert info.value.field == "gravity[1]"


def test_constructor_rejects_wrong_types_with_input_error() -> None:
    with pytest.raises(InputError):
        Scene("code", (Square(center=(0.0, 2.0), mass="1.0"),))  # type: ignore[arg-type]


# ------------------------------------------------------------------ the library
def _library_names() -> list[str]:
    """Every library name with ``N`` replaced by a small number, plus bare family names."""
    names = [name.replace("-N", f"-{SMALL_N}") for name in scene_names()]
    return names + [name.removesuffix("-N") for name in scene_names() if name.endswith("-N")]


def test_library_lists_the_documented_scenes() -> None:
    names = scene_names()
    assert len(names) == len(set(names))
    for expected in ("single-drop", "tilted-drop", "stack-N", "overlap-recovery", "fast-drop"):
        assert expected in names


@pytest.mark.parametrize("name", [name.replace("-N", f"-{SMALL_N}") for name in scene_names()])
def test_every_library_scene_builds_under_its_name(name: str) -> None:
    scene = Scene.named(name)
    assert isinstance(scene, Scene)
    assert scene.name == name
    assert scene.n_boxes >= 1
    assert scene.initial_points().shape == (4 * scene.n_boxes, 2)
    assert scene.initial_velocities().shape == (4 * scene.n_boxes, 2)
    assert Scene.from_dict(scene.to_dict()) == scene


@pytest.mark.parametrize("name", _library_names())
def test_library_scenes_without_allow_overlap_do_not_overlap(name: str) -> None:
    scene = Scene.named(name)
    if scene.allow_overlap:
        pytest.skip("scene overlaps on purpose")
    squares = [s.corners() for s in scene.squares]
    tables = [t.corners() for t in scene.tables]
    if len(squares) > EXHAUSTIVE_PAIRS_LIMIT:  # large-pyramid: 12.7 million pairs
        # all pairs whose bounding circles meet (the metric's k-d tree), and the first
        # ones pair by pair and against the tables below
        model = Model.from_scene(scene)
        assert deepest_overlap(model, scene.initial_points()) <= OVERLAP_TOLERANCE
        squares = squares[:EXHAUSTIVE_PAIRS_LIMIT]
    for a, b in itertools.combinations(squares, 2):
        assert polygon_overlap_depth(a, b) <= OVERLAP_TOLERANCE
    for a, b in itertools.product(squares, tables):
        assert polygon_overlap_depth(a, b) <= OVERLAP_TOLERANCE


@pytest.mark.parametrize("name", _library_names())
def test_library_tables_have_their_top_face_at_y_zero(name: str) -> None:
    scene = Scene.named(name)
    if not scene.tables:
        assert scene.name == "spinning-flight"  # the only scene in free flight
        return
    assert float(np.max(scene.tables[0].corners()[:, 1])) == pytest.approx(0.0, abs=1e-12)
    assert float(np.min(scene.initial_points()[:, 1])) >= -OVERLAP_TOLERANCE


OVERLAP_SCENES = ("overlap-recovery", "corner-overlap", "corner-overlap-wedged",
                  "overlap-recovery-friction")


@pytest.mark.parametrize("name", OVERLAP_SCENES)
def test_only_the_overlap_scenes_allow_overlap_and_need_it(name: str) -> None:
    allowing = {name for name in _library_names() if Scene.named(name).allow_overlap}
    assert allowing == set(OVERLAP_SCENES)
    scene = Scene.named(name)
    with pytest.raises(InputError, match="overlaps squares\\[1\\]") as info:
        dataclasses.replace(scene, allow_overlap=False)
    assert info.value.field == "squares[0]"


@pytest.mark.parametrize("count", [1, SMALL_N, 10])
def test_stack_squares_touch_exactly(count: int) -> None:
    scene = Scene.named(f"stack-{count}")
    assert scene.n_boxes == count
    assert scene.tables == (FLOOR,)
    assert float(np.max(FLOOR.corners()[:, 1])) == 0.0
    centers = np.array([s.center for s in scene.squares])
    np.testing.assert_array_equal(centers[:, 0], 0.0)
    np.testing.assert_array_equal(np.diff(centers[:, 1]), 1.0)
    assert all(s.size == 1.0 and s.angle == 0.0 for s in scene.squares)
    points = scene.initial_points()
    assert float(np.min(points[:4, 1])) == 0.0  # the bottom square stands on the floor top
    for k in range(count - 1):
        assert float(np.max(points[4 * k:4 * k + 4, 1])) == float(
            np.min(points[4 * k + 4:4 * k + 8, 1]))
        assert polygon_overlap_depth(points[4 * k:4 * k + 4], points[4 * k + 4:4 * k + 8]) == 0.0
    np.testing.assert_array_equal(scene.initial_velocities(), 0.0)


def test_family_names_without_number_use_the_default() -> None:
    assert Scene.named("stack").n_boxes == 10
    assert Scene.named("pyramid").n_boxes == 4 + 3 + 2 + 1
    assert Scene.named("rain").n_boxes == 20
    heavy = Scene.named("heavy-on-light")
    assert heavy.name == "heavy-on-light"
    assert [s.mass for s in heavy.squares] == [1.0, 1.0, 100.0]
    assert [s.mass for s in Scene.named("heavy-on-light-7").squares] == [1.0, 1.0, 7.0]


def test_overlap_recovery_overlaps_by_a_quarter_side() -> None:
    scene = Scene.named("overlap-recovery")
    assert scene.allow_overlap is True
    lower, upper = scene.squares
    assert lower.size == upper.size
    depth = polygon_overlap_depth(lower.corners(), upper.corners())
    assert depth == pytest.approx(0.25 * lower.size, abs=1e-12)
    assert polygon_overlap_depth(lower.corners(), scene.tables[0].corners()) == 0.0


def test_fast_drop_moves_more_than_half_a_side_in_one_step() -> None:
    scene = Scene.named("fast-drop")
    dt = 1.0 / 60.0
    (square,) = scene.squares
    displacement = np.linalg.norm(scene.initial_velocities(), axis=1) * dt
    assert np.all(displacement > 0.5 * square.size)
    assert float(np.linalg.norm(square.velocity)) * dt == pytest.approx(2.0 / 3.0)


@pytest.mark.parametrize("name", ["no-such-scene", "stack-three", "single-drop-3", "", "stack_3",
                                  "fast-drop-N"])
def test_unknown_names_raise_and_list_the_named_scenes(name: str) -> None:
    with pytest.raises(InputError) as info:
        Scene.named(name)
    text = str(info.value)
    assert f"unknown scene '{name}'" in text
    for known in scene_names():
        assert known in text


@pytest.mark.parametrize("name", ["stack-0", "pyramid-0"])
def test_family_number_zero_is_rejected(name: str) -> None:
    with pytest.raises(InputError, match="positive integer"):
        Scene.named(name)


@pytest.mark.parametrize(("spelling", "canonical"), [
    ("STACK-3", "stack-3"), ("Tilted-Drop", "tilted-drop"), ("  Fast-DROP ", "fast-drop"),
    ("Overlap-Recovery", "overlap-recovery"), ("HEAVY-ON-LIGHT", "heavy-on-light"),
])
def test_named_is_case_insensitive(spelling: str, canonical: str) -> None:
    scene = Scene.named(spelling)
    assert scene == Scene.named(canonical)
    assert scene.name == canonical
