"""Islands and sleep: squares at rest cost nothing until something touches them.

An *island* is a set of squares connected through square-square contacts (tables do not
connect: two stacks on one floor are two islands).  A square is *still* while its
fastest corner moves slower than :attr:`SleepSettings.speed`; an island falls asleep once
every square in it has been still for :attr:`SleepSettings.time`.  A sleeping island is
frozen (velocities zero, positions unchanged) and left out of the step's QP.  Islands are
recomputed from contacts every step, so an awake square that comes within contact reach
of a sleeping one joins its island, whose stillness is then that of its least still
member: the whole island wakes in the same step and takes part in the QP.

By default the awake islands are solved together as one QP over the awake squares (a
model restricted by :meth:`wuerfel_cvx.model.Model.subset`).  With
``simulate(..., islands=True)`` each awake island is its own QP on its own restricted
model, cached by its own structure, so a resting stack keeps its compiled structure while
a separate pile changes.  Both give the same answer to solver tolerance (no row couples two
islands; islands are found with at least the formulation's contact reach).  One QP per
island costs more, because every QP pays a fixed per-call cost (building, the solve call,
the residual check, the update: about 1-3 ms) that exceeds a small island's solver time.
Measured (velocity, dt = 0.01 s, 100 steps, one run each on a loaded 2-core machine,
median step time joint -> per island, and median step / solver time)::

    scene                      solver     step (ms)       step / solver
    rain-50                    OSQP       24   -> 183      3.2 -> 24
    rain-50                    CLARABEL   16   -> 128      3.4 -> 14
    stack-20 + falling square  OSQP        5.8 ->   7.5    3.0 -> 13
    stack-20 + falling square  CLARABEL    6.6 ->   8.9    1.8 ->  4.9
    two separated 10-stacks    OSQP        6.4 ->   9.0    4.2 -> 14
    two separated 10-stacks    CLARABEL    6.5 ->  10.9    1.6 ->  5.9

(rain-50 has up to 50 islands per step while the squares fall apart.)  The joint QP is
therefore the default; ``islands=True`` is there for scenes with few large islands whose
structures change independently.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .contacts import Contacts
from .geometry import FloatArray
from .model import IntArray, Model, State


@dataclass(frozen=True)
class SleepSettings:
    """When an island falls asleep."""

    speed: float = 1e-4
    """A square is still while every corner is slower than this (m/s)."""
    time: float = 0.5
    """An island sleeps once all its squares have been still this long (s)."""


def island_labels(n_boxes: int, contacts: Contacts) -> IntArray:
    """Island index of each square ``(n,)``: components of the square-square contacts."""
    between_squares = (contacts.point_body < n_boxes) & (contacts.edge_body < n_boxes)
    a = contacts.point_body[between_squares]
    b = contacts.edge_body[between_squares]
    graph = sp.coo_array((np.ones(a.size), (a, b)), shape=(n_boxes, n_boxes))
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

    n_boxes: int
    settings: SleepSettings = field(default_factory=SleepSettings)
    still_for: FloatArray = field(init=False)
    """Seconds each square has been still (s)."""

    def __post_init__(self) -> None:
        self.still_for = np.zeros(self.n_boxes)

    def asleep(self, contacts: Contacts) -> np.ndarray:
        """Boolean ``(n,)``: squares in islands whose every member has been still long enough.

        ``contacts`` are the step's contacts (with the step's reach), so an awake square
        near a sleeping island joins it and wakes it.
        """
        return self.asleep_islands(island_labels(self.n_boxes, contacts))

    def asleep_islands(self, labels: IntArray) -> np.ndarray:
        """As :meth:`asleep`, from the island index of each square ``(n,)``."""
        least_still = np.full(labels.max(initial=-1) + 1, np.inf)
        np.minimum.at(least_still, labels, self.still_for)
        return np.asarray(least_still[labels] >= self.settings.time)

    def record(self, velocities: FloatArray, dt: float) -> None:
        """Update stillness after a step from the corner velocities ``(4 n, 2)`` (m/s)."""
        fastest = np.linalg.norm(velocities, axis=1).reshape(-1, 4).max(axis=1)
        self.still_for = np.where(fastest < self.settings.speed, self.still_for + dt, 0.0)


@dataclass(frozen=True)
class StepPlan:
    """Which boxes each QP of one step takes."""

    groups: tuple[IntArray | None, ...]
    """Boxes (ascending indices) of each QP; ``None``: every box, in one QP of the model."""
    all_asleep: bool = False
    """Every island sleeps: no QP at all, nothing moves."""


class IslandPlanner:
    """Plans each step's QPs from the state's contacts: sleep and islands.

    Without sleep settings and islands every step is one QP over every box.  With sleep,
    islands whose every box has been still long enough are left out; with ``islands``,
    each awake island is its own QP.  The contacts are the step's own (searched with the
    formulation's reach), so no QP row joins two islands.
    """

    def __init__(self, n_boxes: int, sleep: SleepSettings | None, islands: bool):
        self.n_boxes = n_boxes
        self.tracker = SleepTracker(n_boxes, sleep) if sleep is not None else None
        self.islands = islands
        self._all_asleep = False

    def plan(self, contacts: Contacts) -> StepPlan:
        """The QPs of the step whose state has ``contacts``."""
        if self.tracker is None and not self.islands:
            return StepPlan((None,))
        if self._all_asleep:  # nothing moved in the last step: it all sleeps still
            return StepPlan((), all_asleep=True)
        labels = island_labels(self.n_boxes, contacts)
        asleep = (self.tracker.asleep_islands(labels) if self.tracker is not None
                  else np.zeros(self.n_boxes, dtype=bool))
        if self.tracker is not None and bool(asleep.all()):
            self._all_asleep = True
            return StepPlan((), all_asleep=True)
        if self.islands:
            return StepPlan(tuple(island_members(labels, ~asleep)) or (None,))
        if asleep.any():
            return StepPlan((np.flatnonzero(~asleep),))
        return StepPlan((None,))

    def record(self, velocities: FloatArray, dt: float) -> None:
        """Update stillness after a step (corner velocities ``(4 n, 2)``, m/s; ``dt`` s)."""
        if self.tracker is not None:
            self.tracker.record(velocities, dt)


def restrict(model: Model, state: State, contacts: Contacts,
             boxes: IntArray | None) -> tuple[Model, State, Contacts]:
    """The model, state and contacts of the QP over ``boxes`` (``None``: all of them)."""
    if boxes is None:
        return model, state, contacts
    corners = _corner_rows(boxes)
    return (model.subset(boxes), State(state.points[corners], state.velocities[corners]),
            contacts.restricted(boxes, model.n_boxes, model.n_tables))


def merge(state: State, parts: list[tuple[IntArray | None, State]]) -> State:
    """The state after a step from each QP's moved boxes; boxes in no part stay frozen.

    A frozen (sleeping) box keeps its position with zero velocity.
    """
    if len(parts) == 1 and parts[0][0] is None:
        return parts[0][1]
    points = state.points.copy()
    velocities = np.zeros_like(state.velocities)
    for boxes, moved in parts:
        assert boxes is not None, "a QP over every box is the step's only QP"
        corners = _corner_rows(boxes)
        points[corners] = moved.points
        velocities[corners] = moved.velocities
    return State(points, velocities)


def _corner_rows(boxes: IntArray) -> IntArray:
    """Rows of the corners of ``boxes`` in the points array, box by box."""
    return np.asarray((4 * boxes[:, None] + np.arange(4)).ravel(), dtype=np.int64)
