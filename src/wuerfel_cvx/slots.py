"""Slot structures: contact rows laid out by body pair, so a structure survives contacts.

A compiled step problem (:mod:`wuerfel_cvx.compiled`) is keyed by its QP's sparsity
pattern, and the exact rows' pattern changes whenever a contact appears, goes, or moves to
another corner or edge: in a pile nearly every step, and each new pattern pays cvxpy's
canonicalisation.  Yet in rigid coordinates a contact row touches the same six unknowns,
those of its two bodies, whatever corner and edge are involved (in corner coordinates the
same sixteen, of which it uses six).  So the rows can be laid out by *body pair*:

* each pair in the broad phase holds a fixed number of row *slots* per block of rows
  (:data:`FIRST_SLOTS`, grown for a pair that needs more), each slot's pattern all the
  columns of the pair's bodies;
* a contact of the pair fills one of its slots (explicit zeros where its row has none);
* an unused slot is a row that always holds: ``0 x >= -1`` (zeros and a finite slack,
  :data:`UNUSED_SLACK`), with a zero multiplier at every solution.

The padded QP has the exact QP's minimiser, and the exact rows' multipliers are the padded
rows' at their slots, so the answer is mapped back and checked by the KKT residuals on the
exact QP.  Its structure is that of the slot layout, which changes only when the set of
pairs does.  That set is a broad phase with hysteresis, as Box2D's *fat AABBs*: each body's
bounding box is enlarged by :data:`FAT_MARGIN` and kept until the body leaves it; pairs are
the bodies (and tables) whose fat boxes overlap, plus any pair that has a contact.  A pair
that parts therefore keeps its slots until one of its bodies leaves its fat box.

The layout is laid out once per set of pairs and block count, sorted by pair, so equal sets
give equal structures.  It applies to QPs over every body of the model with one block of
rows per contact and no friction cones; other QPs are solved in their exact rows.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .formulations.qp import StepQP
from .geometry import FloatArray
from .model import IntArray, Model
from .warm_start import WarmStart

FAT_MARGIN = 0.1
"""Margin (m) by which a body's bounding box is enlarged, Box2D's ``B2_AABB_MARGIN``."""

FIRST_SLOTS = 2
"""Row slots per pair and block at first, and the step by which a pair that needs more
grows (a face resting on a face has four rows: two corners each way).  Every slot is a row
for the solver, so a pair starts with few."""

LOOKAHEAD = 4.0
"""Steps of motion by which a new fat box reaches ahead (Box2D 2.4's ``b2_aabbMultiplier``)."""

UNUSED_SLACK = 1.0
"""An unused slot's row is ``0 x >= -UNUSED_SLACK`` (in the units of the QP's rows)."""

Pair = tuple[int, int]


@dataclass(frozen=True)
class _Layout:
    """One set of pairs' slots for one block, and the padded pattern of all blocks."""

    keys: IntArray
    """Sorted pair keys ``low * n_bodies + high``."""
    starts: IntArray
    """First slot of each pair within a block."""
    low: IntArray
    """Per slot of a block: the pair's lower-numbered body (always a box)."""
    high: IntArray
    """Per slot: the other body (a table has no columns)."""
    indptr: np.ndarray
    indices: np.ndarray
    """The padded pattern of ``blocks`` blocks (canonical CSR)."""
    slots: int
    blocks: int


@dataclass
class SlotLayout:
    """The broad phase with hysteresis and the slot layout it gives; stateful per run."""

    columns_per_body: int
    """Unknowns per body: 3 in rigid coordinates, 8 in corner velocities."""
    fat_margin: float = FAT_MARGIN
    first_slots: int = FIRST_SLOTS
    changes: int = 0
    """Slot layouts laid out for a QP (the first, and one per change of the pairs or of a
    pair's slots between two QPs): each is a new structure."""
    padded: int = 0
    """QPs solved in a slot structure."""
    _fat: FloatArray | None = field(default=None, repr=False)
    _pairs: dict[Pair, int] = field(default_factory=dict, repr=False)
    _layout: _Layout | None = field(default=None, repr=False)
    _n_boxes: int = 0
    _n_bodies: int = 0

    def track(self, model: Model, points: FloatArray, velocities: FloatArray,
              dt: float) -> None:
        """Follow the bodies to ``points`` (m): new fat boxes for those that left theirs.

        A new fat box is the body's box enlarged by :attr:`fat_margin` and stretched along
        its motion by :data:`LOOKAHEAD` steps of its corners' mean velocity (m/s), as
        Box2D stretches a moving body's fat box by its displacement.
        """
        corners = points.reshape(-1, 4, 2)
        tight = np.concatenate([corners.min(axis=1), corners.max(axis=1)], axis=1)
        if self._fat is None or self._fat.shape != tight.shape:
            self._n_boxes, self._n_bodies = tight.shape[0], tight.shape[0] + model.n_tables
            left = np.ones(tight.shape[0], dtype=bool)
            self._fat = tight.copy()
        else:
            left = np.any(tight[:, :2] < self._fat[:, :2], axis=1) | np.any(
                tight[:, 2:] > self._fat[:, 2:], axis=1)
            if not np.any(left):
                return
        travel = LOOKAHEAD * dt * velocities.reshape(-1, 4, 2)[left].mean(axis=1)
        fat = tight[left] + np.array([-1.0, -1.0, 1.0, 1.0]) * self.fat_margin
        fat[:, :2] += np.minimum(travel, 0.0)
        fat[:, 2:] += np.maximum(travel, 0.0)
        self._fat[left] = fat
        kept = set(self._pairs) & self._overlapping(model, self.fat_margin)
        self._set_pairs(self._overlapping(model, 0.0) | kept)

    def pad(self, qp: StepQP) -> tuple[StepQP, IntArray] | None:
        """``qp`` in the slot structure, and the padded row of each exact row; or ``None``.

        ``None`` when the layout does not apply (see the module docstring).
        """
        contacts, count, rows = qp.contacts, len(qp.contacts), qp.n_inequalities
        if (self._fat is None or qp.cones is not None
                or qp.n_variables != self.columns_per_body * self._n_boxes
                or (count == 0 and rows) or (count and rows % count)):
            return None
        blocks = rows // count if count else (self._layout.blocks if self._layout else 1)
        low = np.minimum(contacts.point_body, contacts.edge_body).astype(np.int64)
        high = np.maximum(contacts.point_body, contacts.edge_body).astype(np.int64)
        keys = low * self._n_bodies + high
        order = np.argsort(keys, kind="stable")
        sorted_keys = keys[order]
        first = np.ones(count, dtype=bool)
        first[1:] = sorted_keys[1:] != sorted_keys[:-1]
        group_start = np.flatnonzero(first)
        rank = np.empty(count, dtype=np.int64)
        rank[order] = np.arange(count) - np.repeat(group_start, np.diff(
            np.append(group_start, count)))
        self._admit(low, high, rank)
        layout = self._current(blocks)
        pair = np.searchsorted(layout.keys, keys)
        slot = layout.starts[pair] + rank
        padded_rows = (np.arange(blocks)[:, None] * layout.slots + slot[None, :]).ravel()
        self.padded += 1
        return self._padded(qp, layout, padded_rows), padded_rows

    def _padded(self, qp: StepQP, layout: _Layout, padded_rows: IntArray) -> StepQP:
        """``qp``'s rows written into ``layout``'s slots (``padded_rows``: where each goes)."""
        g = qp.ineq_matrix
        entry_row = padded_rows[np.repeat(np.arange(g.shape[0]), np.diff(g.indptr))]
        slot = entry_row % max(layout.slots, 1)
        low, high = layout.low[slot], layout.high[slot]
        width, col = self.columns_per_body, g.indices.astype(np.int64)
        in_low = (col >= width * low) & (col < width * (low + 1))
        in_high = (high < self._n_boxes) & (col >= width * high) & (col < width * (high + 1))
        if not np.all(in_low | in_high):
            raise ValueError("a contact row has an entry outside its pair's columns")
        position = np.where(in_low, col - width * low, width + col - width * high)
        data = np.zeros(layout.indices.shape[0])
        data[layout.indptr[entry_row] + position] = g.data
        n_rows = layout.blocks * layout.slots
        matrix = sp.csr_array((data, layout.indices, layout.indptr),
                              shape=(n_rows, qp.n_variables))
        matrix.has_canonical_format = True  # each slot's columns ascending, no duplicates
        rhs = np.full(n_rows, -UNUSED_SLACK)
        rhs[padded_rows] = qp.ineq_rhs
        upper = None
        if qp.ineq_upper is not None:
            upper = np.full(n_rows, np.inf)
            upper[padded_rows] = qp.ineq_upper
        return StepQP(weights=qp.weights, target=qp.target, eq_matrix=qp.eq_matrix,
                      eq_rhs=qp.eq_rhs, ineq_matrix=matrix, ineq_rhs=rhs,
                      contacts=qp.contacts, ineq_upper=upper, cost_factor=qp.cost_factor,
                      linearised_about=qp.linearised_about)

    def _admit(self, low: IntArray, high: IntArray, rank: IntArray) -> None:
        """Make room for contacts: their pairs, and enough slots for each pair's count."""
        changed = False
        for a, b, r in zip(low.tolist(), high.tolist(), rank.tolist(), strict=True):
            slots = self._pairs.get((a, b), 0)
            if r >= slots:
                self._pairs[(a, b)] = (r // self.first_slots + 1) * self.first_slots
                changed = True
        if changed:
            self._layout = None

    def _set_pairs(self, pairs: set[Pair]) -> None:
        """Take ``pairs`` as the broad phase's, keeping the slots of pairs that stay."""
        if pairs == set(self._pairs):
            return
        self._pairs = {pair: self._pairs.get(pair, self.first_slots) for pair in sorted(pairs)}
        self._layout = None

    def _overlapping(self, model: Model, extra: float) -> set[Pair]:
        """Pairs of bodies (box-box, box-table) whose fat boxes, grown by ``extra`` (m), overlap."""
        assert self._fat is not None
        fat, pairs = self._fat + np.array([-1.0, -1.0, 1.0, 1.0]) * extra, set()
        centre, half = (fat[:, :2] + fat[:, 2:]) / 2, (fat[:, 2:] - fat[:, :2]) / 2
        reach = 2.0 * float(np.max(np.linalg.norm(half, axis=1), initial=0.0))
        candidates = cKDTree(centre).query_pairs(reach, output_type="ndarray")
        if candidates.size:
            a, b = candidates[:, 0], candidates[:, 1]
            overlap = np.all(np.abs(centre[a] - centre[b]) <= half[a] + half[b], axis=1)
            pairs |= {(int(i), int(j)) for i, j in zip(np.minimum(a, b)[overlap],
                                                       np.maximum(a, b)[overlap], strict=True)}
        if model.n_tables:
            table = model.table_points.reshape(-1, 4, 2)
            box = np.concatenate([table.min(axis=1), table.max(axis=1)], axis=1)
            hit = ((fat[:, None, 0] <= box[None, :, 2]) & (box[None, :, 0] <= fat[:, None, 2])
                   & (fat[:, None, 1] <= box[None, :, 3]) & (box[None, :, 1] <= fat[:, None, 3]))
            boxes, tables = np.nonzero(hit)
            pairs |= {(int(i), int(self._n_boxes + j)) for i, j in zip(boxes, tables,
                                                                       strict=True)}
        return pairs

    def _current(self, blocks: int) -> _Layout:
        """The layout of the current pairs for ``blocks`` blocks (laid out once)."""
        if self._layout is not None and self._layout.blocks == blocks:
            return self._layout
        pairs = sorted(self._pairs)
        counts = np.array([self._pairs[pair] for pair in pairs], dtype=np.int64)
        keys = np.array([a * self._n_bodies + b for a, b in pairs], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        low = np.repeat(np.array([a for a, _ in pairs], dtype=np.int64), counts)
        high = np.repeat(np.array([b for _, b in pairs], dtype=np.int64), counts)
        width = self.columns_per_body
        columns = [np.concatenate([np.arange(width * a, width * (a + 1)),
                                   np.arange(width * b, width * (b + 1))
                                   if b < self._n_boxes else np.zeros(0, np.int64)])
                   for a, b in zip(low.tolist(), high.tolist(), strict=True)] * blocks
        lengths = np.array([c.size for c in columns], dtype=np.int64)
        indptr = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
        indices = (np.concatenate(columns) if columns else np.zeros(0)).astype(np.int32)
        self._layout = _Layout(keys=keys, starts=starts, low=low, high=high, indptr=indptr,
                               indices=indices, slots=int(counts.sum()), blocks=blocks)
        self.changes += 1
        return self._layout


def padded_warm_start(warm: WarmStart | None, padded_rows: IntArray,
                      n_rows: int) -> WarmStart | None:
    """``warm`` (exact rows) on the padded rows: unused slots start at zero."""
    if warm is None:
        return None
    ineq_dual = np.zeros(n_rows)
    ineq_dual[padded_rows] = warm.ineq_dual
    return WarmStart(x=warm.x, eq_dual=warm.eq_dual, ineq_dual=ineq_dual,
                     matched_rows=warm.matched_rows)
