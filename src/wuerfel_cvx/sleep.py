"""Islands and sleep: squares at rest cost nothing until something touches them.

An *island* is a set of squares connected through square-square contacts (tables do not
connect: two stacks on one floor are two islands).  A square is *still* while its
fastest corner moves slower than :attr:`SleepSettings.speed`; an island falls asleep once
every square in it has been still for :attr:`SleepSettings.time`.  A sleeping island is
frozen (velocities zero, positions unchanged) and left out of the step's QP.  Islands are
recomputed from contacts every step, so an awake square that comes within contact reach
of a sleeping one joins its island, whose stillness is then that of its least still
member: the whole island wakes in the same step and takes part in the QP.

The awake islands are solved together as one QP over the awake squares (a model
restricted by :meth:`wuerfel_cvx.model.Model.subset`).  Separately solved islands would
give the same answer (they share no rows), but each solve would pay cvxpy's fixed
per-call cost, which today exceeds a small island's solver time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .contacts import Contacts
from .geometry import FloatArray
from .model import IntArray


@dataclass(frozen=True)
class SleepSettings:
    """When an island falls asleep."""

    speed: float = 1e-4
    """A square is still while every corner is slower than this (m/s)."""
    time: float = 0.5
    """An island sleeps once all its squares have been still this long (s)."""


def island_labels(n_squares: int, contacts: Contacts) -> IntArray:
    """Island index of each square ``(n,)``: components of the square-square contacts."""
    between_squares = (contacts.point_body < n_squares) & (contacts.edge_body < n_squares)
    a = contacts.point_body[between_squares]
    b = contacts.edge_body[between_squares]
    graph = sp.coo_array((np.ones(a.size), (a, b)), shape=(n_squares, n_squares))
    _, labels = connected_components(graph, directed=False)
    return np.asarray(labels, dtype=np.int64)


def island_members(labels: IntArray, awake: np.ndarray | None = None) -> list[IntArray]:
    """The squares of each island (ascending), islands ordered by their first square.

    ``labels`` ``(n,)`` from :func:`island_labels`; with ``awake`` (boolean ``(n,)``) only
    the islands of awake squares.
    """
    squares = np.arange(labels.size) if awake is None else np.flatnonzero(awake)
    if squares.size == 0:
        return []
    order = np.argsort(labels[squares], kind="stable")  # ascending squares within an island
    grouped = squares[order]
    cuts = np.flatnonzero(np.diff(labels[grouped])) + 1
    members = np.split(grouped, cuts)
    members.sort(key=lambda island: int(island[0]))
    return members


@dataclass
class SleepTracker:
    """Per-square stillness over time, and which squares sleep at a step."""

    n_squares: int
    settings: SleepSettings = field(default_factory=SleepSettings)
    still_for: FloatArray = field(init=False)
    """Seconds each square has been still (s)."""

    def __post_init__(self) -> None:
        self.still_for = np.zeros(self.n_squares)

    def asleep(self, contacts: Contacts) -> np.ndarray:
        """Boolean ``(n,)``: squares in islands whose every member has been still long enough.

        ``contacts`` are the step's contacts (with the step's reach), so an awake square
        near a sleeping island joins it and wakes it.
        """
        return self.asleep_islands(island_labels(self.n_squares, contacts))

    def asleep_islands(self, labels: IntArray) -> np.ndarray:
        """As :meth:`asleep`, from the island index of each square ``(n,)``."""
        least_still = np.full(labels.max(initial=-1) + 1, np.inf)
        np.minimum.at(least_still, labels, self.still_for)
        return np.asarray(least_still[labels] >= self.settings.time)

    def record(self, velocities: FloatArray, dt: float) -> None:
        """Update stillness after a step from the corner velocities ``(4 n, 2)`` (m/s)."""
        fastest = np.linalg.norm(velocities, axis=1).reshape(-1, 4).max(axis=1)
        self.still_for = np.where(fastest < self.settings.speed, self.still_for + dt, 0.0)
