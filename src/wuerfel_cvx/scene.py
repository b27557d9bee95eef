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
Every number must be finite and within the ranges of :data:`LIMITS`, so that the
geometry and the step QPs built from a scene that loads stay finite.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .errors import InputError
from .geometry import FloatArray, polygon_overlap_depth, rectangle_corners, rot90, square_corners

Vec2 = tuple[float, float]

#: Initial overlap (m) between bodies that a scene may have without ``allow_overlap``.
OVERLAP_TOLERANCE = 1e-6

DEFAULT_GRAVITY: Vec2 = (0.0, -9.81)


@dataclass(frozen=True)
class Limit:
    """The accepted range of one kind of quantity in a scene."""

    largest: float
    """Largest magnitude accepted (in ``unit``)."""
    smallest: float = 0.0
    """Smallest magnitude accepted for a positive quantity (0: none)."""
    unit: str = ""


LIMITS: dict[str, Limit] = {
    # Coordinates and lengths: the geometry squares them (rod errors, signed areas), so
    # 1e308 overflows to inf and 1e-308 underflows to 0.  Within 1e6 m the spacing of
    # doubles (1.2e-10 m) is far below the overlap tolerance (1e-6 m), which is also
    # the smallest side that can be told apart from touching.
    "position": Limit(1e6, unit="m"),
    "length": Limit(1e6, smallest=OVERLAP_TOLERANCE, unit="m"),
    # Masses become the QP's weights; 1e6 kg to 1e-6 kg keeps their ratio (1e12) within
    # what the solvers' scaling handles and the KKT residuals can check.
    "mass": Limit(1e6, smallest=1e-6, unit="kg"),
    # Speeds and gravity set the contact reach (dt |v| + dt^2 |g|) and the QP's target.
    "speed": Limit(1e6, unit="m/s"),
    "angular_speed": Limit(1e6, unit="rad/s"),
    "acceleration": Limit(1e6, unit="m/s^2"),
}
"""Ranges of the numbers in a scene; beyond them a step's data is no longer finite or
meaningful, so such a scene is an :class:`InputError` rather than a failed step."""


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
        except RecursionError:  # tomllib parses nested arrays and tables recursively
            raise InputError("malformed TOML (arrays or tables nested too deeply)",
                             source=source) from None
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
    def n_boxes(self) -> int:
        """Number of moving bodies (squares and boxes)."""
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
    try:
        number = float(value)
    except OverflowError:  # TOML integers have no size limit in tomllib
        raise InputError(f"out of range, got an integer of {len(str(value))} digits",
                         source=source, field=where) from None
    if not math.isfinite(number):
        raise InputError(f"must be finite, got {value}", source=source, field=where)
    return number


def _positive(value: Any, source: str, where: str) -> float:
    number = _number(value, source, where)
    if number <= 0.0:
        raise InputError(f"must be positive, got {value}", source=source, field=where)
    return number


def _within(value: float, kind: str, source: str, where: str) -> None:
    """Check ``value`` against ``LIMITS[kind]``."""
    limit = LIMITS[kind]
    unit = f" {limit.unit}" if limit.unit else ""
    if abs(value) > limit.largest:
        raise InputError(f"out of range: magnitude at most {limit.largest:g}{unit}, "
                         f"got {value:g}", source=source, field=where)
    if abs(value) < limit.smallest:
        raise InputError(f"out of range: at least {limit.smallest:g}{unit}, got {value:g}",
                         source=source, field=where)


def _vector_within(value: Any, kind: str, source: str, where: str) -> Vec2:
    vector = _vector(value, source, where)
    for axis, component in enumerate(vector):
        _within(component, kind, source, f"{where}[{axis}]")
    return vector


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
        key = _printable_key(unknown[0])
        raise InputError(
            f"unknown key '{unknown[0]}' (allowed: {', '.join(sorted(keys))})"
            if key == unknown[0] else
            f"unknown key {key} (allowed: {', '.join(sorted(keys))})",
            source=source, field=f"{where}.{key}" if where else key,
        )
    return value


def _printable_key(key: str) -> str:
    """``key`` as written, or quoted with escapes if it is not a bare TOML key.

    An empty key, spaces, or invisible characters (a right-to-left override, a BOM)
    would make the error line blank, confusing or scrambled.
    """
    if re.fullmatch(r"[A-Za-z0-9_-]+", key):
        return key
    return json.dumps(key, ensure_ascii=not key.isprintable())


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
    _vector_within(list(scene.gravity), "acceleration", source, "gravity")
    for index, sq in enumerate(scene.squares):
        where = f"squares[{index}]"
        if not isinstance(sq, Square):
            raise InputError(f"expected a Square, got {type(sq).__name__}", source=source,
                             field=where)
        _vector_within(list(sq.center), "position", source, f"{where}.center")
        _vector_within(list(sq.velocity), "speed", source, f"{where}.velocity")
        _number(sq.angle, source, f"{where}.angle")
        _within(_number(sq.angular_velocity, source, f"{where}.angular_velocity"),
                "angular_speed", source, f"{where}.angular_velocity")
        _within(_positive(sq.size, source, f"{where}.size"), "length", source,
                f"{where}.size")
        _within(_positive(sq.mass, source, f"{where}.mass"), "mass", source, f"{where}.mass")
    for index, tb in enumerate(scene.tables):
        where = f"tables[{index}]"
        if not isinstance(tb, Table):
            raise InputError(f"expected a Table, got {type(tb).__name__}", source=source,
                             field=where)
        _vector_within(list(tb.center), "position", source, f"{where}.center")
        _number(tb.angle, source, f"{where}.angle")
        for axis, value in enumerate(_vector(list(tb.size), source, f"{where}.size")):
            _within(_positive(value, source, f"{where}.size[{axis}]"), "length", source,
                    f"{where}.size[{axis}]")
    if not scene.allow_overlap:
        _check_no_overlap(scene)


def _check_no_overlap(scene: Scene) -> None:
    """Raise for the first overlapping pair (squares first, then tables, in index order).

    A :class:`~scipy.spatial.cKDTree` on the square centres and one distance test per
    table keep only pairs whose bounding circles meet, so a scene of thousands of
    squares loads in well under a second instead of testing every pair.
    """
    names = ([f"squares[{i}]" for i in range(scene.n_boxes)]
             + [f"tables[{j}]" for j in range(len(scene.tables))])
    polygons = [s.corners() for s in scene.squares] + [t.corners() for t in scene.tables]
    for a, b in _candidate_pairs(scene):
        depth = polygon_overlap_depth(polygons[a], polygons[b])
        if depth > OVERLAP_TOLERANCE:
            raise InputError(
                f"overlaps {names[b]} by {depth:.3g} m at the start "
                "(set allow_overlap = true to permit it)",
                source=scene.source, field=names[a],
            )


def _candidate_pairs(scene: Scene) -> list[tuple[int, int]]:
    """Body pairs ``(a, b)``, ``a`` a square and ``a < b``, whose bounding circles meet.

    Bodies are numbered squares first, then tables; pairs come sorted.
    """
    n = scene.n_boxes
    centers = np.array([s.center for s in scene.squares], dtype=np.float64)
    radii = np.array([s.size for s in scene.squares]) / math.sqrt(2)
    found = cKDTree(centers).query_pairs(2.0 * float(radii.max()), output_type="ndarray")
    first, second = found[:, 0], found[:, 1]
    near = (np.linalg.norm(centers[first] - centers[second], axis=1)
            <= radii[first] + radii[second])
    pairs = {(int(a), int(b)) for a, b in np.sort(found[near], axis=1)}
    for j, table in enumerate(scene.tables):
        reach = radii + math.hypot(*table.size) / 2
        touching = np.linalg.norm(centers - np.asarray(table.center), axis=1) <= reach
        pairs.update((int(a), n + j) for a in np.flatnonzero(touching))
    return sorted(pairs)
