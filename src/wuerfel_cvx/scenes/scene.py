"""Scenes: squares, boxes and fixed tables under gravity, their TOML form and its checks.

A scene file has exactly this schema (SI units, angles in radians counter-clockwise;
every key but ``center`` has a default)::

    name = "plank-on-a-table"
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

    [[boxes]]
    center = [4.0, 2.0]
    size = [2.0, 0.5]         # width, height (m); default [1.0, 1.0]
    angle = 0.2               # and the other keys of [[squares]], with the same defaults
    mass = 1.0
    velocity = [0.0, 0.0]
    angular_velocity = 0.0

A scene needs at least one square or box.  The moving bodies are numbered squares
first, then boxes, each group in file order (:attr:`Scene.bodies`): the model's rows,
the initial state, the overlap check and the peer engines all use that order.

The bodies are value types.  A :class:`Square` (side ``size``) and a :class:`Box`
(``size = (width, height)``) are the same mechanical body, 4 corner masses joined by 5
rods; a square is a box whose width and height are equal, kept as its own type for the
seed's scalar ``size``.  Both offer ``width``, ``height``, :meth:`~Box.corners` and
:meth:`~Box.corner_velocities`, so code that moves bodies takes either
(:data:`MovingBody`).  A :class:`Table` never moves.

Loading never executes or unpickles anything: it is :mod:`tomllib` and checks.
:func:`parse_scene` turns a parsed TOML mapping into the arguments of :class:`Scene`, and
:func:`check_scene` (run by the scene's constructor) checks the values of any scene,
loaded or built in code.  Every number must be finite and within the ranges of
:data:`LIMITS`, so that the geometry and the step QPs built from a scene that loads stay
finite.  Every problem is an :class:`~wuerfel_cvx.errors.InputError` of one line naming
the file and the dotted field, e.g. ``plank.toml: boxes[0].size[1]: must be positive,
got -0.5``.
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from scipy.spatial import cKDTree

from ..errors import InputError
from .geometry import (
    FloatArray,
    polygon_overlap_depth,
    polygon_overlap_depths,
    rectangle_corners,
    rot90,
)

Vec2 = tuple[float, float]


class _RigidRectangle:
    """What a square and a box share: corners and their rigid velocities from the pose.

    The subclass holds the pose fields (``center``, ``angle``, ``velocity``,
    ``angular_velocity``) and says its ``width`` and ``height``.
    """

    center: Vec2
    angle: float
    velocity: Vec2
    angular_velocity: float

    @property
    def width(self) -> float:
        """Extent (m) along the body's own x axis."""
        raise NotImplementedError

    @property
    def height(self) -> float:
        """Extent (m) along the body's own y axis."""
        raise NotImplementedError

    def corners(self) -> FloatArray:
        """Corner positions ``(4, 2)`` (m), counter-clockwise from the lower-left one."""
        return rectangle_corners(self.center, self.width, self.height, self.angle)

    def corner_velocities(self) -> FloatArray:
        """Corner velocities ``(4, 2)`` (m/s) of the rigid motion: ``v + omega rot90(r)``."""
        offsets = self.corners() - np.asarray(self.center)
        return np.asarray(self.velocity) + self.angular_velocity * rot90(offsets)


@dataclass(frozen=True)
class Square(_RigidRectangle):
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
    friction: float = 0.0
    """Coulomb friction coefficient (1), >= 0; a contact's is ``sqrt(mu_a mu_b)``."""

    @property
    def width(self) -> float:
        """Extent (m) along the body's own x axis: the side length."""
        return self.size

    @property
    def height(self) -> float:
        """Extent (m) along the body's own y axis: the side length."""
        return self.size


@dataclass(frozen=True)
class Box(_RigidRectangle):
    """A rigid rectangle of any width and height: 4 corner masses joined by 5 rods."""

    center: Vec2
    """Centre position (m)."""
    size: Vec2 = (1.0, 1.0)
    """Width and height (m), along the box's own x and y axes at ``angle`` 0."""
    angle: float = 0.0
    """Orientation (rad, counter-clockwise)."""
    mass: float = 1.0
    """Total mass (kg), split equally over the 4 corners."""
    velocity: Vec2 = (0.0, 0.0)
    """Velocity of the centre (m/s)."""
    angular_velocity: float = 0.0
    """Angular velocity (rad/s, counter-clockwise)."""
    friction: float = 0.0
    """Coulomb friction coefficient (1), >= 0; a contact's is ``sqrt(mu_a mu_b)``."""

    @property
    def width(self) -> float:
        """Extent (m) along the box's own x axis."""
        return self.size[0]

    @property
    def height(self) -> float:
        """Extent (m) along the box's own y axis."""
        return self.size[1]


MovingBody = Square | Box
"""A body the step moves: a square or a box."""


def half_diagonal(body: MovingBody) -> float:
    """Distance (m) from a body's centre to each of its corners (its circumradius)."""
    return math.hypot(body.width, body.height) / 2.0


@dataclass(frozen=True)
class Table:
    """A fixed rectangular body: never moves, has no variables in the QP."""

    center: Vec2
    """Centre position (m)."""
    size: Vec2 = (20.0, 1.0)
    """Width and height (m)."""
    angle: float = 0.0
    """Orientation (rad, counter-clockwise)."""
    friction: float = 0.0
    """Coulomb friction coefficient (1), >= 0; a contact's is ``sqrt(mu_a mu_b)``."""

    def corners(self) -> FloatArray:
        """Corner positions ``(4, 2)`` (m), counter-clockwise."""
        return rectangle_corners(self.center, self.size[0], self.size[1], self.angle)


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
    # A friction coefficient scales the tangential rows of the friction cone; beyond 100
    # the cone is a wall to any slip, and larger values only spread the rows' scales.
    "friction": Limit(100.0),
}
"""Ranges of the numbers in a scene; beyond them a step's data is no longer finite or
meaningful, so such a scene is an :class:`InputError` rather than a failed step.  Every
side of a square, box or table is a ``"length"``."""

SCENE_KEYS = frozenset({"name", "gravity", "allow_overlap", "tables", "squares", "boxes"})
"""The keys of a scene file's top level."""
MOVING_KEYS = frozenset({"center", "size", "angle", "mass", "velocity", "angular_velocity",
                         "friction"})
"""The keys of a ``[[squares]]`` or ``[[boxes]]`` entry."""
TABLE_KEYS = frozenset({"center", "size", "angle", "friction"})
"""The keys of a ``[[tables]]`` entry."""


# ---------------------------------------------------------------------- values
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


def _vector(value: Any, source: str, where: str) -> Vec2:
    if isinstance(value, tuple):  # a value built in code
        value = list(value)
    if not isinstance(value, list) or len(value) != 2:
        raise InputError("expected a list of two numbers", source=source, field=where)
    return (_number(value[0], source, f"{where}[0]"), _number(value[1], source, f"{where}[1]"))


def _vector_within(value: Any, kind: str, source: str, where: str) -> Vec2:
    vector = _vector(value, source, where)
    for axis, component in enumerate(vector):
        _within(component, kind, source, f"{where}[{axis}]")
    return vector


def _sides_within(value: Any, source: str, where: str) -> None:
    """Check a ``[width, height]`` pair: two positive lengths within ``LIMITS``."""
    for axis, side in enumerate(_vector(value, source, where)):
        _within(_positive(side, source, f"{where}[{axis}]"), "length", source,
                f"{where}[{axis}]")


# ---------------------------------------------------------------------- tables of keys
def _table_of(value: Any, source: str, where: str, keys: frozenset[str]) -> Mapping[str, Any]:
    """``value`` as a TOML table, all of whose keys are in ``keys``.

    Every unknown key is named, in one line: ``unknown key 'x'`` (field ``where.x``) or
    ``unknown keys 'x', 'y'`` (field ``where``).
    """
    if not isinstance(value, Mapping):
        raise InputError(f"expected a table, got {type(value).__name__}", source=source,
                         field=where)
    unknown = [(key, _printable_key(key)) for key in sorted(set(value) - keys)]
    if unknown:
        # a bare key in single quotes; one that needs escapes is already double-quoted
        quoted = [f"'{key}'" if shown == key else shown for key, shown in unknown]
        allowed = f"(allowed: {', '.join(sorted(keys))})"
        if len(unknown) == 1:
            raise InputError(f"unknown key {quoted[0]} {allowed}", source=source,
                             field=f"{where}.{unknown[0][1]}" if where else unknown[0][1])
        raise InputError(f"unknown keys {', '.join(quoted)} {allowed}", source=source,
                         field=where or None)
    return value


def _printable_key(key: str) -> str:
    """``key`` as written, or quoted with escapes if it is not a bare TOML key.

    An empty key, spaces, or invisible characters (a right-to-left override, a BOM)
    would make the error line blank, confusing or scrambled.
    """
    if re.fullmatch(r"[A-Za-z0-9_-]+", key):
        return key
    return json.dumps(key, ensure_ascii=not key.isprintable())


def _entries(data: Mapping[str, Any], key: str, allowed: frozenset[str],
             source: str) -> list[tuple[str, Mapping[str, Any]]]:
    """The ``[[key]]`` tables of a scene, each checked for unknown keys and a ``center``."""
    value = data.get(key, [])
    if not isinstance(value, list):
        raise InputError(f"expected an array of tables ([[{key}]])", source=source, field=key)
    entries = []
    for index, raw in enumerate(value):
        where = f"{key}[{index}]"
        entry = _table_of(raw, source, where, allowed)
        if "center" not in entry:
            raise InputError("missing required key 'center'", source=source,
                             field=f"{where}.center")
        entries.append((where, entry))
    return entries


# ---------------------------------------------------------------------- parsing
def parse_scene(data: Mapping[str, Any], source: str) -> dict[str, Any]:
    """The keyword arguments of :class:`~wuerfel_cvx.scenes.scene.Scene` for a parsed TOML file.

    Types and keys are checked here; ranges and overlaps by :func:`check_scene`.
    """
    data = _table_of(data, source, "", SCENE_KEYS)
    name = data.get("name", Path(source).stem if source.endswith(".toml") else "scene")
    if not isinstance(name, str) or not name:
        raise InputError("expected a non-empty string", source=source, field="name")
    gravity = _vector(data.get("gravity", list(DEFAULT_GRAVITY)), source, "gravity")
    allow_overlap = data.get("allow_overlap", False)
    if not isinstance(allow_overlap, bool):
        raise InputError("expected true or false", source=source, field="allow_overlap")
    tables = tuple(
        Table(  # sizes are checked positive by check_scene
            center=_vector(entry["center"], source, f"{where}.center"),
            size=_vector(entry.get("size", [20.0, 1.0]), source, f"{where}.size"),
            angle=_number(entry.get("angle", 0.0), source, f"{where}.angle"),
            friction=_friction(entry.get("friction", 0.0), source, f"{where}.friction"),
        ) for where, entry in _entries(data, "tables", TABLE_KEYS, source))
    squares = tuple(
        Square(size=_positive(entry.get("size", 1.0), source, f"{where}.size"),
               **_motion(entry, source, where))
        for where, entry in _entries(data, "squares", MOVING_KEYS, source))
    boxes = tuple(  # sides are checked positive by check_scene, each as size[i]
        Box(size=_vector(entry.get("size", [1.0, 1.0]), source, f"{where}.size"),
            **_motion(entry, source, where))
        for where, entry in _entries(data, "boxes", MOVING_KEYS, source))
    return {"name": name, "squares": squares, "boxes": boxes, "tables": tables,
            "gravity": gravity, "allow_overlap": allow_overlap, "source": source}


def _motion(entry: Mapping[str, Any], source: str, where: str) -> dict[str, Any]:
    """The fields a square and a box share, with their defaults."""
    return {
        "center": _vector(entry["center"], source, f"{where}.center"),
        "angle": _number(entry.get("angle", 0.0), source, f"{where}.angle"),
        "mass": _positive(entry.get("mass", 1.0), source, f"{where}.mass"),
        "velocity": _vector(entry.get("velocity", [0.0, 0.0]), source, f"{where}.velocity"),
        "angular_velocity": _number(entry.get("angular_velocity", 0.0), source,
                                    f"{where}.angular_velocity"),
        "friction": _friction(entry.get("friction", 0.0), source, f"{where}.friction"),
    }


def _friction(value: Any, source: str, where: str) -> float:
    """A friction coefficient: a finite number, 0 to ``LIMITS["friction"]``."""
    number = _number(value, source, where)
    if number < 0.0:
        raise InputError(f"must be non-negative, got {value}", source=source, field=where)
    _within(number, "friction", source, where)
    return number


# ---------------------------------------------------------------------- checking
def check_scene(scene: Scene) -> None:
    """Check the values of a scene, built in code or loaded, the way the loader does."""
    source = scene.source
    if not scene.squares and not scene.boxes:
        raise InputError("a scene needs at least one square or box", source=source,
                         field="squares")
    _vector_within(scene.gravity, "acceleration", source, "gravity")
    _check_moving(scene.squares, Square, "squares", source)
    _check_moving(scene.boxes, Box, "boxes", source)
    for index, tb in enumerate(scene.tables):
        where = f"tables[{index}]"
        if not isinstance(tb, Table):
            raise InputError(f"expected a Table, got {type(tb).__name__}", source=source,
                             field=where)
        _vector_within(tb.center, "position", source, f"{where}.center")
        _number(tb.angle, source, f"{where}.angle")
        _friction(tb.friction, source, f"{where}.friction")
        _sides_within(tb.size, source, f"{where}.size")
    if not scene.allow_overlap:
        _check_no_overlap(scene)


def _check_moving(bodies: Sequence[MovingBody], kind: type[Square] | type[Box], group: str,
                  source: str) -> None:
    """Check the squares or the boxes of a scene (``group`` names them in errors)."""
    for index, body in enumerate(bodies):
        where = f"{group}[{index}]"
        if not isinstance(body, kind):
            raise InputError(f"expected a {kind.__name__}, got {type(body).__name__}",
                             source=source, field=where)
        _vector_within(body.center, "position", source, f"{where}.center")
        _vector_within(body.velocity, "speed", source, f"{where}.velocity")
        _number(body.angle, source, f"{where}.angle")
        _within(_number(body.angular_velocity, source, f"{where}.angular_velocity"),
                "angular_speed", source, f"{where}.angular_velocity")
        if isinstance(body, Box):
            _sides_within(body.size, source, f"{where}.size")
        else:
            _within(_positive(body.size, source, f"{where}.size"), "length", source,
                    f"{where}.size")
        _within(_positive(body.mass, source, f"{where}.mass"), "mass", source,
                f"{where}.mass")
        _friction(body.friction, source, f"{where}.friction")


def _check_no_overlap(scene: Scene) -> None:
    """Raise for the first overlapping pair (squares, then boxes, then tables, by index).

    A :class:`~scipy.spatial.cKDTree` on the moving bodies' centres and one distance test
    per table keep only pairs whose bounding circles meet, and one batched separating-axis
    test screens them, so a scene of thousands of touching bodies (``large-pyramid``)
    loads in a fraction of a second instead of testing every pair.
    """
    names = ([f"squares[{i}]" for i in range(len(scene.squares))]
             + [f"boxes[{i}]" for i in range(len(scene.boxes))]
             + [f"tables[{j}]" for j in range(len(scene.tables))])
    shapes = [*scene.bodies, *scene.tables]
    pairs = np.array(_candidate_pairs(scene), dtype=np.intp).reshape(-1, 2)
    corners = np.array([shape.corners() for shape in shapes]).reshape(-1, 4, 2)
    # all pairs at once; then the pairwise test (whose rounding decides) on those near it
    screened = polygon_overlap_depths(corners[pairs[:, 0]], corners[pairs[:, 1]])
    for a, b in pairs[screened > 0.5 * OVERLAP_TOLERANCE]:
        depth = polygon_overlap_depth(corners[a], corners[b])
        if depth > OVERLAP_TOLERANCE:
            raise InputError(
                f"overlaps {names[b]} by {depth:.3g} m at the start "
                "(set allow_overlap = true to permit it)",
                source=scene.source, field=names[a],
            )


def _candidate_pairs(scene: Scene) -> list[tuple[int, int]]:
    """Body pairs ``(a, b)``, ``a`` a moving body and ``a < b``, whose bounding circles meet.

    Bodies are numbered as in :attr:`~wuerfel_cvx.scenes.scene.Scene.bodies`, then the tables;
    pairs come sorted.  A body's circle is centred on it with its half diagonal as radius.
    """
    n = scene.n_boxes
    centers = np.array([b.center for b in scene.bodies], dtype=np.float64)
    radii = np.array([half_diagonal(b) for b in scene.bodies])
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


@dataclass(frozen=True)
class Scene:
    """Squares, boxes and fixed tables under uniform gravity.

    Build one from a TOML file (:meth:`from_toml`), by name (:meth:`named`), or
    directly; the constructor checks everything :meth:`from_toml` checks.
    """

    name: str
    squares: tuple[Square, ...] = ()
    tables: tuple[Table, ...] = ()
    gravity: Vec2 = DEFAULT_GRAVITY
    """Gravitational acceleration (m/s^2)."""
    allow_overlap: bool = False
    """Accept bodies that overlap at the start (for overlap-recovery studies)."""
    boxes: tuple[Box, ...] = ()
    """Boxes of any width and height; they follow the squares in :attr:`bodies`."""
    source: str = field(default="<scene>", compare=False)
    """Where the scene came from, used in error messages."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "squares", tuple(self.squares))
        object.__setattr__(self, "boxes", tuple(self.boxes))
        object.__setattr__(self, "tables", tuple(self.tables))
        check_scene(self)

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
        return cls(**parse_scene(data, source))

    @classmethod
    def named(cls, name: str) -> Scene:
        """A scene from the package's library, e.g. ``Scene.named("stack-10")``."""
        from .library import named_scene

        return named_scene(name)

    def to_dict(self) -> dict[str, Any]:
        """The scene in the TOML schema (the inverse of :meth:`from_dict`).

        ``boxes`` is written only when the scene has any, so a scene of squares keeps
        the seed's schema.
        """
        data: dict[str, Any] = {
            "name": self.name,
            "gravity": list(self.gravity),
            "allow_overlap": self.allow_overlap,
            "tables": [
                _with_friction({"center": list(t.center), "size": list(t.size),
                                "angle": t.angle}, t.friction)
                for t in self.tables
            ],
            "squares": [_body_dict(s, s.size) for s in self.squares],
        }
        if self.boxes:
            data["boxes"] = [_body_dict(b, list(b.size)) for b in self.boxes]
        return data

    def to_toml(self) -> str:
        """The scene as a TOML file of the schema: :meth:`to_dict`, each vector on one line.

        :func:`tomllib.loads` of it gives :meth:`to_dict` back, so it loads to an equal scene.
        """
        data = self.to_dict()
        groups = {key: data.pop(key) for key in ("tables", "squares", "boxes")
                  if data.get(key)}  # an empty group stays a `key = []` line
        lines = [f"{key} = {_toml_value(value)}" for key, value in data.items()]
        for group, entries in groups.items():
            for entry in entries:
                lines += ["", f"[[{group}]]",
                          *(f"{key} = {_toml_value(value)}" for key, value in entry.items())]
        return "\n".join(lines) + "\n"

    # ------------------------------------------------------------------ arrays
    @property
    def bodies(self) -> tuple[MovingBody, ...]:
        """The moving bodies in the model's order: the squares, then the boxes."""
        return self.squares + self.boxes

    @property
    def n_boxes(self) -> int:
        """Number of moving bodies (squares and boxes)."""
        return len(self.squares) + len(self.boxes)

    def initial_points(self) -> FloatArray:
        """Corner positions ``(4 n, 2)`` (m), body i of :attr:`bodies` at rows 4i..4i+3."""
        return np.concatenate([b.corners() for b in self.bodies])

    def initial_velocities(self) -> FloatArray:
        """Corner velocities ``(4 n, 2)`` (m/s) in the layout of :meth:`initial_points`."""
        return np.concatenate([b.corner_velocities() for b in self.bodies])

    def table_points(self) -> FloatArray:
        """Table corners ``(4 t, 2)`` (m), table j at rows 4j..4j+3, counter-clockwise."""
        if not self.tables:
            return np.zeros((0, 2))
        return np.concatenate([t.corners() for t in self.tables])


def _body_dict(body: MovingBody, size: float | list[float]) -> dict[str, Any]:
    """A square's or a box's TOML table, its keys in the order of the schema."""
    return _with_friction({"center": list(body.center), "size": size, "angle": body.angle,
                           "mass": body.mass, "velocity": list(body.velocity),
                           "angular_velocity": body.angular_velocity}, body.friction)


def _toml_value(value: Any) -> str:
    """A value of the schema in TOML: :mod:`tomli_w`'s, but a list on one line."""
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(item) for item in value) + "]"
    return tomli_w.dumps({"v": value}).removeprefix("v = ").rstrip("\n")


def _with_friction(entry: dict[str, Any], friction: float) -> dict[str, Any]:
    """``entry`` with its ``friction`` key, written only when it is not 0.

    A frictionless scene keeps the seed's schema.
    """
    return {**entry, "friction": friction} if friction else entry
