"""The mechanical model of a scene: point masses, rods, bodies and the state.

Every body owns 4 consecutive rows of the *all-points* array: the moving boxes first
(box ``b`` of :attr:`Scene.bodies <wuerfel_cvx.scenes.scene.Scene.bodies>`, squares then boxes,
at rows ``4b..4b+3``), then tables (table ``t`` at rows ``4(n+t)..4(n+t)+3``), each
counter-clockwise.  A square is a box of equal width and height.  Box corners are the
QP's variables; table corners are constants unless the seed's heavy-table variant is
chosen, in which case they become variables of mass ``table_mass`` held still by an
equality ("Tischrestriktion").
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError
from ..friction.forces import body_friction
from ..scenes.geometry import FloatArray, rectangle_corners
from ..scenes.scene import Scene

IntArray = NDArray[np.int64]

#: The 5 rods of a box as corner pairs: 4 sides and the diagonal 0-2 (seed 2.1); their
#: rest lengths are the box's own width, height and diagonal.
BOX_RODS: tuple[tuple[int, int], ...] = ((0, 1), (1, 2), (2, 3), (3, 0), (0, 2))


@dataclass(frozen=True)
class Model:
    """Arrays derived once from a :class:`~wuerfel_cvx.scenes.scene.Scene`."""

    scene: Scene
    n_boxes: int
    n_tables: int
    box_sizes: FloatArray
    """Width and height of each box (m), shape ``(n, 2)``."""
    point_masses: FloatArray
    """Mass of each box corner (kg), shape ``(4 n,)``: a quarter of the box's mass."""
    rods: IntArray
    """Rod end points ``(5 n, 2)`` as rows of the box-points array."""
    rod_lengths: FloatArray
    """Rest length of each rod (m), shape ``(5 n,)``."""
    table_points: FloatArray
    """Table corners ``(4 t, 2)`` (m), fixed."""
    reference_corners: FloatArray
    """Corners ``(n, 4, 2)`` of each box centred at 0 with angle 0 (m).

    A box's moment of inertia about its centre is ``sum m_i |r_i|^2 = m (w^2 + h^2) / 4``
    (kg m^2) over these corners."""
    gravity: FloatArray
    """Gravitational acceleration ``(2,)`` (m/s^2)."""
    table_mass: float | None = None
    """``None``: tables are constants.  A number (kg per corner): the seed's heavy table."""
    friction: FloatArray = field(default_factory=lambda: np.zeros(0))
    """Coulomb coefficient (1) of every body ``(n + t,)``: the boxes, then the tables."""

    @classmethod
    def from_scene(
        cls, scene: Scene, *, table_mass: float | None = None, extra_rod: bool = False
    ) -> Model:
        """Derive the model; ``extra_rod`` adds the redundant second diagonal 1-3."""
        if table_mass is not None and not (np.isfinite(table_mass) and table_mass > 0):
            raise InputError(f"table_mass must be a positive finite number, got {table_mass}",
                             field="table_mass")
        n = scene.n_boxes
        bodies = scene.bodies
        sizes = np.array([[b.width, b.height] for b in bodies], dtype=np.float64).reshape(-1, 2)
        masses = np.repeat(np.array([b.mass for b in bodies]) / 4.0, 4)
        pairs = BOX_RODS + (((1, 3),) if extra_rod else ())
        rods = np.array([[4 * b + i, 4 * b + j] for b in range(n) for i, j in pairs],
                        dtype=np.int64)
        reference = np.stack([rectangle_corners((0.0, 0.0), w, h, 0.0) for w, h in sizes])
        flat_reference = reference.reshape(-1, 2)
        lengths = np.linalg.norm(flat_reference[rods[:, 0]] - flat_reference[rods[:, 1]], axis=1)
        return cls(
            scene=scene, n_boxes=n, n_tables=len(scene.tables), box_sizes=sizes,
            point_masses=masses, rods=rods, rod_lengths=lengths,
            table_points=scene.table_points(), reference_corners=reference,
            gravity=np.asarray(scene.gravity, dtype=np.float64), table_mass=table_mass,
            friction=body_friction(scene),
        )

    def subset(self, squares: IntArray) -> Model:
        """The same model restricted to ``squares`` (indices, ascending); all tables kept.

        Square ``squares[k]`` becomes square ``k``; rods and corner masses follow it.
        """
        squares = np.asarray(squares, dtype=np.int64)
        rods_per_square = self.rods.shape[0] // max(self.n_boxes, 1)
        blocks = self.rods.reshape(self.n_boxes, rods_per_square, 2)[squares]
        shift = 4 * (np.arange(squares.size) - squares)[:, None, None]
        corners = (4 * squares[:, None] + np.arange(4)).ravel()
        return replace(
            self, n_boxes=int(squares.size), box_sizes=self.box_sizes[squares],
            point_masses=self.point_masses[corners], rods=(blocks + shift).reshape(-1, 2),
            rod_lengths=self.rod_lengths.reshape(self.n_boxes, -1)[squares].ravel(),
            reference_corners=self.reference_corners[squares],
            friction=np.concatenate([self.friction[squares], self.friction[self.n_boxes:]]),
        )

    @cached_property
    def total_mass(self) -> float:
        """The boxes' mass (kg): the sum of their corners'."""
        return float(np.sum(self.point_masses))

    @cached_property
    def gravity_norm(self) -> float:
        """``|g|`` (m/s^2)."""
        return float(np.linalg.norm(self.gravity))

    @cached_property
    def has_friction(self) -> bool:
        """Whether any body has a Coulomb coefficient above 0 (else no contact has friction)."""
        return bool(np.any(self.friction > 0.0))

    @property
    def n_points(self) -> int:
        """Number of square corners (the moving points)."""
        return 4 * self.n_boxes

    @property
    def n_bodies(self) -> int:
        """Squares plus tables."""
        return self.n_boxes + self.n_tables

    def all_points(self, points: FloatArray) -> FloatArray:
        """Square corners followed by table corners, ``(4 (n + t), 2)`` (m)."""
        return np.concatenate([points, self.table_points])


@dataclass(frozen=True)
class State:
    """Positions and velocities of the square corners at one instant."""

    points: FloatArray
    """Corner positions ``(4 n, 2)`` (m)."""
    velocities: FloatArray
    """Corner velocities ``(4 n, 2)`` (m/s)."""

    @classmethod
    def initial(cls, scene: Scene) -> State:
        """The scene's initial state."""
        return cls(scene.initial_points(), scene.initial_velocities())
