"""Scenes: squares and fixed tables under gravity, and their TOML form.

A scene file has exactly this schema (SI units, angles in radians counter-clockwise;
every key but ``center`` has a default)::

    name = "tilted-drop"
    gravity = [0.0, -9.81]
    allow_overlap = false

    [[tables]]
    center = [0.0, -0.5]
    size = [20.0, 1.0]        # width, height (m)
    angle = 0.0

    [[squares]]
    center = [0.0, 2.0]
    size = 1.0                # side length (m)
    angle = 0.3
    mass = 1.0                # kg, split equally over the 4 corners
    velocity = [0.0, 0.0]     # m/s
    angular_velocity = 0.0    # rad/s

Loading never executes or unpickles anything: it is :mod:`tomllib` and checks.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .geometry import FloatArray, polygon_overlap_depth, rectangle_corners, rot90, square_corners

Vec2 = tuple[float, float]

#: Initial overlap (m) between bodies that a scene may have without ``allow_overlap``.
OVERLAP_TOLERANCE = 1e-6

DEFAULT_GRAVITY: Vec2 = (0.0, -9.81)


@dataclass(frozen=True)
class Square:
    """A rigid square: 4 corner masses joined by 5 rods."""

    center: Vec2
    """Centre position (m)."""
    size: float = 1.0
    """Side length (m)."""
    angle: float = 0.0
    """Orientation (rad, counter-clockwise)."""
    mass: float = 1.0
    """Total mass (kg), split equally over the 4 corners."""
    velocity: Vec2 = (0.0, 0.0)
    """Velocity of the centre (m/s)."""
    angular_velocity: float = 0.0
    """Angular velocity (rad/s, counter-clockwise)."""

    def corners(self) -> FloatArray:
        """Corner positions ``(4, 2)`` (m), counter-clockwise."""
        return square_corners(self.center, self.size, self.angle)

    def corner_velocities(self) -> FloatArray:
        """Corner velocities ``(4, 2)`` (m/s) of the rigid motion."""
        offsets = self.corners() - np.asarray(self.center)
        return np.asarray(self.velocity) + self.angular_velocity * rot90(offsets)


@dataclass(frozen=True)
class Table:
    """A fixed rectangular body: never moves, has no variables in the QP."""

    center: Vec2
    """Centre position (m)."""
    size: Vec2 = (20.0, 1.0)
    """Width and height (m)."""
    angle: float = 0.0
    """Orientation (rad, counter-clockwise)."""

    def corners(self) -> FloatArray:
        """Corner positions ``(4, 2)`` (m), counter-clockwise."""
        return rectangle_corners(self.center, self.size[0], self.size[1], self.angle)


@dataclass(frozen=True)
class Scene:
    """Squares and fixed tables under uniform gravity.

    Build one from a TOML file (:meth:`from_toml`), by name (:meth:`named`), or
    directly; the constructor checks everything :meth:`from_toml` checks.
    """

    name: str
    squares: tuple[Square, ...]
    tables: tuple[Table, ...] = ()
    gravity: Vec2 = DEFAULT_GRAVITY
    """Gravitational acceleration (m/s^2)."""
    allow_overlap: bool = False
    """Accept squares that overlap at the start (for overlap-recovery studies)."""
    source: str = field(default="<scene>", compare=False)
    """Where the scene came from, used in error messages."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "squares", tuple(self.squares))
        object.__setattr__(self, "tables", tuple(self.tables))
        _check_scene(self)

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_toml(cls, path: str | Path) -> Scene:
        """Load and check a scene file; raises :class:`InputError` naming file and field."""
        path = Path(path)
        source = str(path)
        try:
            text = path.read_bytes()
        except FileNotFoundError:
            raise InputError("file not found", source=source) from None
        except OSError as exc:
            raise InputError(f"cannot read file ({exc.strerror})", source=source) from None
        try:
            data = tomllib.loads(text.decode("utf-8"))
        except UnicodeDecodeError:
            raise InputError("not UTF-8 text", source=source) from None
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"malformed TOML ({exc})", source=source) from None
        return cls.from_dict(data, source=source)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = "<dict>") -> Scene:
        """Build a scene from the parsed TOML mapping (same schema, same checks)."""
        return _scene_from_mapping(data, source)

    @classmethod
    def named(cls, name: str) -> Scene:
        """A scene from the package's library, e.g. ``Scene.named("stack-10")``."""
        from .library import named_scene

        return named_scene(name)

    def to_dict(self) -> dict[str, Any]:
        """The scene in the TOML schema (the inverse of :meth:`from_dict`)."""
        return {
            "name": self.name,
            "gravity": list(self.gravity),
            "allow_overlap": self.allow_overlap,
            "tables": [
                {"center": list(t.center), "size": list(t.size), "angle": t.angle}
                for t in self.tables
            ],
            "squares": [
                {
                    "center": list(s.center),
                    "size": s.size,
                    "angle": s.angle,
                    "mass": s.mass,
                    "velocity": list(s.velocity),
                    "angular_velocity": s.angular_velocity,
                }
                for s in self.squares
            ],
        }

    # ------------------------------------------------------------------ arrays
    @property
    def n_squares(self) -> int:
        """Number of squares."""
        return len(self.squares)

    def initial_points(self) -> FloatArray:
        """Corner positions ``(4 n, 2)`` (m); square i at rows 4i..4i+3, counter-clockwise."""
        if not self.squares:
            return np.zeros((0, 2))
        return np.concatenate([s.corners() for s in self.squares])

    def initial_velocities(self) -> FloatArray:
        """Corner velocities ``(4 n, 2)`` (m/s) in the layout of :meth:`initial_points`."""
        if not self.squares:
            return np.zeros((0, 2))
        return np.concatenate([s.corner_velocities() for s in self.squares])

    def table_points(self) -> FloatArray:
        """Table corners ``(4 t, 2)`` (m), table j at rows 4j..4j+3, counter-clockwise."""
        if not self.tables:
            return np.zeros((0, 2))
        return np.concatenate([t.corners() for t in self.tables])


# ---------------------------------------------------------------------- parsing
_SCENE_KEYS = {"name", "gravity", "allow_overlap", "tables", "squares"}
_SQUARE_KEYS = {"center", "size", "angle", "mass", "velocity", "angular_velocity"}
_TABLE_KEYS = {"center", "size", "angle"}


def _number(value: Any, source: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(f"expected a number, got {type(value).__name__}", source=source,
                         field=where)
    number = float(value)
    if not math.isfinite(number):
        raise InputError(f"must be finite, got {value}", source=source, field=where)
    return number


def _positive(value: Any, source: str, where: str) -> float:
    number = _number(value, source, where)
    if number <= 0.0:
        raise InputError(f"must be positive, got {value}", source=source, field=where)
    return number


def _vector(value: Any, source: str, where: str) -> Vec2:
    if not isinstance(value, list) or len(value) != 2:
        raise InputError("expected a list of two numbers", source=source, field=where)
    return (_number(value[0], source, f"{where}[0]"), _number(value[1], source, f"{where}[1]"))


def _table_of(value: Any, source: str, where: str, keys: set[str]) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise InputError(f"expected a table, got {type(value).__name__}", source=source,
                         field=where)
    unknown = sorted(set(value) - keys)
    if unknown:
        raise InputError(
            f"unknown key '{unknown[0]}' (allowed: {', '.join(sorted(keys))})",
            source=source, field=f"{where}.{unknown[0]}" if where else unknown[0],
        )
    return value


def _list_of_tables(data: Mapping[str, Any], key: str, source: str) -> list[Any]:
    value = data.get(key, [])
    if not isinstance(value, list):
        raise InputError(f"expected an array of tables ([[{key}]])", source=source, field=key)
    return value


def _entries(data: Mapping[str, Any], key: str, allowed: set[str],
             source: str) -> list[tuple[str, Mapping[str, Any]]]:
    """The ``[[key]]`` tables of a scene, each checked for unknown keys and a ``center``."""
    entries = []
    for index, raw in enumerate(_list_of_tables(data, key, source)):
        where = f"{key}[{index}]"
        entry = _table_of(raw, source, where, allowed)
        if "center" not in entry:
            raise InputError("missing required key 'center'", source=source,
                             field=f"{where}.center")
        entries.append((where, entry))
    return entries


def _scene_from_mapping(data: Mapping[str, Any], source: str) -> Scene:
    data = _table_of(data, source, "", _SCENE_KEYS)
    name = data.get("name", Path(source).stem if source.endswith(".toml") else "scene")
    if not isinstance(name, str) or not name:
        raise InputError("expected a non-empty string", source=source, field="name")
    gravity = _vector(data.get("gravity", list(DEFAULT_GRAVITY)), source, "gravity")
    allow_overlap = data.get("allow_overlap", False)
    if not isinstance(allow_overlap, bool):
        raise InputError("expected true or false", source=source, field="allow_overlap")

    tables = []
    for where, entry in _entries(data, "tables", _TABLE_KEYS, source):
        tables.append(Table(  # sizes are checked positive by the Scene constructor
            center=_vector(entry["center"], source, f"{where}.center"),
            size=_vector(entry.get("size", [20.0, 1.0]), source, f"{where}.size"),
            angle=_number(entry.get("angle", 0.0), source, f"{where}.angle"),
        ))

    squares = []
    for where, entry in _entries(data, "squares", _SQUARE_KEYS, source):
        squares.append(Square(
            center=_vector(entry["center"], source, f"{where}.center"),
            size=_positive(entry.get("size", 1.0), source, f"{where}.size"),
            angle=_number(entry.get("angle", 0.0), source, f"{where}.angle"),
            mass=_positive(entry.get("mass", 1.0), source, f"{where}.mass"),
            velocity=_vector(entry.get("velocity", [0.0, 0.0]), source, f"{where}.velocity"),
            angular_velocity=_number(entry.get("angular_velocity", 0.0), source,
                                     f"{where}.angular_velocity"),
        ))
    return Scene(name=name, squares=tuple(squares), tables=tuple(tables), gravity=gravity,
                 allow_overlap=allow_overlap, source=source)


def _check_scene(scene: Scene) -> None:
    """Check values of a scene built in code the way the loader checks a file."""
    source = scene.source
    if not scene.squares:
        raise InputError("a scene needs at least one square", source=source, field="squares")
    _vector(list(scene.gravity), source, "gravity")
    for index, sq in enumerate(scene.squares):
        where = f"squares[{index}]"
        if not isinstance(sq, Square):
            raise InputError(f"expected a Square, got {type(sq).__name__}", source=source,
                             field=where)
        _vector(list(sq.center), source, f"{where}.center")
        _vector(list(sq.velocity), source, f"{where}.velocity")
        _number(sq.angle, source, f"{where}.angle")
        _number(sq.angular_velocity, source, f"{where}.angular_velocity")
        _positive(sq.size, source, f"{where}.size")
        _positive(sq.mass, source, f"{where}.mass")
    for index, tb in enumerate(scene.tables):
        where = f"tables[{index}]"
        if not isinstance(tb, Table):
            raise InputError(f"expected a Table, got {type(tb).__name__}", source=source,
                             field=where)
        _vector(list(tb.center), source, f"{where}.center")
        _number(tb.angle, source, f"{where}.angle")
        for axis, value in enumerate(_vector(list(tb.size), source, f"{where}.size")):
            _positive(value, source, f"{where}.size[{axis}]")
    if not scene.allow_overlap:
        _check_no_overlap(scene)


def _check_no_overlap(scene: Scene) -> None:
    polygons = [(f"squares[{i}]", s.corners(), s.size / math.sqrt(2))
                for i, s in enumerate(scene.squares)]
    bodies = polygons + [(f"tables[{j}]", t.corners(), math.hypot(*t.size) / 2)
                         for j, t in enumerate(scene.tables)]
    centers = np.array([poly.mean(axis=0) for _, poly, _ in bodies])
    for a, (name_a, poly_a, radius_a) in enumerate(polygons):
        for b in range(a + 1, len(bodies)):
            name_b, poly_b, radius_b = bodies[b]
            if np.linalg.norm(centers[a] - centers[b]) > radius_a + radius_b:
                continue
            depth = polygon_overlap_depth(poly_a, poly_b)
            if depth > OVERLAP_TOLERANCE:
                raise InputError(
                    f"overlaps {name_b} by {depth:.3g} m at the start "
                    "(set allow_overlap = true to permit it)",
                    source=scene.source, field=name_a,
                )
