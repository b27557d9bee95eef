"""Finding point-versus-edge contacts: a broad phase and a per-pair contact manifold.

Broad phase
    Square pairs whose bounding circles come within the margin, by their indices: up to
    64 squares from a compiled loop over all pairs, beyond from a
    :class:`scipy.spatial.cKDTree` on square centres, sorted (the tree's own order depends
    on its traversal); squares against tables are checked directly (there are few
    tables).  Only those pairs are examined further.

Manifold rule (one contact normal per body pair, as Box2D's polygon manifolds)
    For each unordered pair of bodies {A, B} (squares and tables) the *reference face*
    is the face, of either body, along whose outward normal the pair is best separated:
    the largest *separation*, the smallest signed distance of the other body's corners
    from the face's line (the separating-axis test).  Separations within
    :data:`TIE_TOLERANCE` tie (an aligned stack); a tie goes to the longer face, then to
    the lower-numbered body (a table is numbered after every square).  The longer face
    holds a small body resting on a large one by its own corners, and no row reaches far
    past the end of a short face.  The other body's *incident face* is its
    face whose normal is most anti-parallel to the reference normal.  Then

    * each corner of the other body is held by the reference face, and
    * each of the reference face's own two corners is held by the incident face,

    if the corner is within the search margin of the face's line and within the face's
    extent: its projection on the line is within :data:`TIE_TOLERANCE` of the face (so
    that corners exactly at a face's end, as in an aligned stack, are kept), or, for a
    corner outside the line and beyond an end by at most the face's length, its distance
    from the face (the segment) is within the search margin: it may reach the face
    within the step, as when two corners approach each other.  (Farther out the line no
    longer stands for the face: its rotation would move the corner more than twice as
    much as the face.)  Such a corner's row may close its *gap*, the corner's distance from
    the face (the segment, reached at the face's end), not its smaller distance from the
    line: the row holds the corner off the face, not off the line extended past the face's
    end, where nothing is (:attr:`Contacts.clearance`).  All rows of a pair then push the
    two bodies apart
    within 45 degrees of the reference normal (the incident face of a rectangle is at
    most that far off it): no two rows of a pair hold the same relative sliding in
    opposite senses.  Each row is still a point against an edge's line, so the
    formulations' rows are unchanged.

    A corner inside the other body of a pair always lies within the face's extent, so
    it has a row unless it is a corner of the reference body off the reference face; a
    corner behind a face's line but beyond the face's end has none.  A row's distance is
    measured along the pair's normal, which can be deeper than the distance to the
    nearest face of the other body.

Compiled loops
    The broad phase yields an array of ordered (edge body, point body) pairs (each
    unordered pair twice, the second half reversed), and one compiled loop over them
    (:mod:`wuerfel_cvx.step.contact_kernel`) applies the manifold rule and the margin test.
    Contacts come out ordered by ordered pair, then by corner.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..scenes.geometry import FloatArray
from . import contact_kernel
from .model import IntArray, Model

#: Lengths closer than this (m) count as equal: two faces' separations (a tie between the
#: bodies goes to the longer face), and a corner's place along a face's line and the
#: face's end (a corner this close to the end is on the face).
TIE_TOLERANCE = contact_kernel.TIE_TOLERANCE


@dataclass(frozen=True)
class Contacts:
    """Point-versus-edge pairs, one row each.

    Indices refer to the all-points array of :meth:`Model.all_points`.  The edge is in
    contact order (clockwise), so ``side_value(p[edge_i], p[edge_j], p[point])`` is
    positive when the point is outside (see :mod:`wuerfel_cvx.scenes.geometry`).
    """

    point: IntArray
    edge_i: IntArray
    edge_j: IntArray
    point_body: IntArray
    edge_body: IntArray
    distance: FloatArray
    """Signed distance (m) of the point from the edge line, positive outside."""
    clearance: FloatArray | None = None
    """How much farther (m) the point is from its face (the segment) than from the face's
    line: ``sqrt(beyond^2 + distance^2) - distance`` for a point whose projection lies
    ``beyond`` past the face's nearer end, 0 for a point on the face; ``None``: 0 for all."""

    def __len__(self) -> int:
        return int(self.point.shape[0])

    @classmethod
    def empty(cls) -> Contacts:
        """No contacts."""
        none = np.zeros(0, dtype=np.int64)
        return cls(none, none, none, none, none, np.zeros(0), np.zeros(0))

    @property
    def gap(self) -> FloatArray:
        """Each point's distance (m) from its face: ``distance``, plus any ``clearance``.

        What the point must travel to reach the face: a row's gap.
        """
        if self.clearance is None:
            return self.distance
        return np.where(self.clearance > 0.0, self.distance + self.clearance, self.distance)

    def deepest_penetration(self) -> float:
        """Depth (m) of the deepest held point behind its edge's line; 0 if none is.

        The depth is along the point's pair normal (the module docstring).  The same for
        any search margin >= 0: the chosen edges do not depend on the margin, and a point
        behind its edge (distance < 0) is within every such margin.
        """
        if len(self) == 0:
            return 0.0
        return float(max(0.0, -np.min(self.distance)))

    def selected(self, keep: NDArray[np.bool_]) -> Contacts:
        """The contacts where ``keep`` ``(len,)`` is true, in their order, every field kept."""
        return Contacts(point=self.point[keep], edge_i=self.edge_i[keep],
                        edge_j=self.edge_j[keep], point_body=self.point_body[keep],
                        edge_body=self.edge_body[keep], distance=self.distance[keep],
                        clearance=None if self.clearance is None else self.clearance[keep])

    def restricted(self, boxes: IntArray, n_boxes: int, n_tables: int) -> Contacts:
        """The contacts among ``boxes`` (ascending) and the tables, renumbered for them.

        The numbering is that of :meth:`Model.subset` of a model with ``n_boxes`` boxes and
        ``n_tables`` tables: box ``boxes[k]`` becomes box ``k``, the tables follow the kept
        boxes.  Contacts with a box not in ``boxes`` are dropped; the others keep their order.
        """
        new_body = np.full(n_boxes + n_tables, -1, dtype=np.int64)
        new_body[boxes] = np.arange(boxes.size)
        new_body[n_boxes:] = boxes.size + np.arange(n_tables)
        kept = self.selected((new_body[self.point_body] >= 0) & (new_body[self.edge_body] >= 0))

        def renumbered(points: IntArray) -> IntArray:
            return 4 * new_body[points // 4] + points % 4

        return replace(kept, point=renumbered(kept.point), edge_i=renumbered(kept.edge_i),
                       edge_j=renumbered(kept.edge_j), point_body=new_body[kept.point_body],
                       edge_body=new_body[kept.edge_body])

    def ids(self, boxes: IntArray | None = None, n_boxes: int = 0) -> IntArray:
        """Each contact's identity ``(point, edge_i, edge_j)``, ``(len, 3)`` int64.

        The contact's name across steps (:mod:`wuerfel_cvx.step.identity`), in the whole model's
        numbering: for contacts :meth:`restricted` to ``boxes`` of a model with ``n_boxes``
        boxes, the numbering is mapped back (its inverse); ``None``: they are numbered so
        already.
        """
        points = np.stack((self.point, self.edge_i, self.edge_j), axis=1, dtype=np.int64)
        if boxes is None:
            return points
        body = points // 4
        kept = body < boxes.size
        old = np.where(kept, boxes[np.minimum(body, boxes.size - 1)],
                       n_boxes + body - boxes.size)
        return np.asarray(4 * old + points % 4, dtype=np.int64)


def _lengths(vectors: FloatArray) -> FloatArray:
    """Euclidean lengths (m) over the last axis (size 2), as ``np.linalg.norm`` computes them.

    ``sqrt(x x + y y)``: the same operations in the same order, so the same bits, without
    ``norm``'s per-call overhead.
    """
    x, y = vectors[..., 0], vectors[..., 1]
    return np.asarray(np.sqrt(x * x + y * y), dtype=np.float64)


def body_pairs(model: Model, all_points: FloatArray, reach: FloatArray) -> IntArray:
    """Ordered (edge body, point body) pairs that may touch, ``(P, 2)``.

    ``reach`` ``(n_bodies,)`` (m) is how far beyond its circumcircle each body must be
    looked for.  Table-table pairs are never returned.  Order: the square pairs within
    reach (by first, then second index), then the square-table pairs, then all of them
    reversed.  Compiled loops (:mod:`wuerfel_cvx.step.contact_kernel`) over the candidate
    square pairs of :func:`~wuerfel_cvx.step.contact_kernel.candidate_pairs`.
    """
    n = model.n_boxes
    centers, bound = contact_kernel.bounds(all_points.reshape(-1, 4, 2), reach)
    candidates = (contact_kernel.candidate_pairs(centers[:n], 2.0 * float(bound[:n].max()))
                  if n > 1 else np.zeros((0, 2), dtype=np.int64))
    return contact_kernel.pairs_within(centers, bound, candidates, n)


def pair_distances(corners: FloatArray, edge_body: IntArray, point_body: IntArray) -> FloatArray:
    """Signed distances (m) of each point body's corners from the edge body's edge lines.

    ``corners`` ``(n_bodies, 4, 2)`` (m), counter-clockwise; ``edge_body`` and
    ``point_body`` ``(P,)``.  Entry ``[k, e, p]`` of the ``(4, 4, P)`` result is corner
    ``k`` of ``point_body[p]`` against edge ``e`` (corner ``e`` to ``e + 1``) of
    ``edge_body[p]``, positive outside.  The pair axis is last so that every operation
    runs over long contiguous rows.  The arithmetic is that of
    :func:`~wuerfel_cvx.scenes.geometry.edge_distances`, so the values agree with it bit for bit.
    """
    head = np.roll(corners, -1, axis=1)  # contact order (i, j) = (head, tail)
    edge = corners - head  # p_j - p_i, (n_bodies, 4, 2)
    length = _lengths(edge)  # (n_bodies, 4)

    def of_edges(values: FloatArray) -> FloatArray:  # (n_bodies, 4) -> (1, 4 edges, P)
        return values.T.take(edge_body, axis=1)[None, :, :]

    def of_points(values: FloatArray) -> FloatArray:  # (n_bodies, 4) -> (4 corners, 1, P)
        return values.T.take(point_body, axis=1)[:, None, :]

    offset_x = of_points(corners[..., 0]) - of_edges(head[..., 0])  # p_k - p_i
    offset_y = of_points(corners[..., 1]) - of_edges(head[..., 1])
    # cross(p_j - p_i, p_k - p_i), as geometry.cross computes it (m^2)
    area = of_edges(edge[..., 0]) * offset_y - of_edges(edge[..., 1]) * offset_x
    return np.asarray(area / of_edges(length), dtype=np.float64)


def find_contacts(
    model: Model, points: FloatArray, margin: FloatArray | float
) -> Contacts:
    """Point-edge contacts whose signed distance is at most ``margin`` (m).

    ``margin`` is a scalar or one value per body ``(n_bodies,)``; a pair uses the sum
    of its two bodies' values.  Returns one row per point that is within reach of a
    foreign body, with the edge chosen by the rule in the module docstring; rows are
    ordered by pair (as from :func:`body_pairs`), then by corner.  A pure function of its
    arguments: the simulation loop calls it once per state and hands the result on.
    """
    reach = np.broadcast_to(np.asarray(margin, dtype=np.float64), (model.n_bodies,))
    return _search(model, points, reach)


def _search(model: Model, points: FloatArray, reach: FloatArray) -> Contacts:
    all_points = model.all_points(points)
    pairs = body_pairs(model, all_points, reach)
    if len(pairs) == 0:
        return Contacts.empty()
    edge_body, point_body = pairs[:, 0], pairs[:, 1]
    pair_index, corner, edge_index, distance, clearance = contact_kernel.narrow_phase(
        all_points.reshape(-1, 4, 2), edge_body, point_body, reach)
    w = edge_body[pair_index]
    return Contacts(
        point=4 * point_body[pair_index] + corner,
        edge_i=4 * w + (edge_index + 1) % 4,
        edge_j=4 * w + edge_index,
        point_body=point_body[pair_index],
        edge_body=w,
        distance=distance,
        clearance=clearance,
    )
