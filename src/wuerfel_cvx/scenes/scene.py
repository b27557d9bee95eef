"""Scenes: squares, boxes and fixed tables under gravity, and their TOML form.

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

Loading never executes or unpickles anything: it is :mod:`tomllib` and checks
(:mod:`wuerfel_cvx.scenes.schema`).  Every number must be finite and within the ranges
of :data:`LIMITS`, so that the geometry and the step QPs built from a scene that loads
stay finite.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from ..errors import InputError
from .bodies import Box, MovingBody, Square, Table, Vec2
from .geometry import FloatArray
from .schema import (
    DEFAULT_GRAVITY,
    LIMITS,
    OVERLAP_TOLERANCE,
    Limit,
    check_scene,
    parse_scene,
)

__all__ = ["DEFAULT_GRAVITY", "LIMITS", "OVERLAP_TOLERANCE", "Box", "Limit", "MovingBody",
           "Scene", "Square", "Table", "Vec2"]


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
