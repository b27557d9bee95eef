"""Point-versus-edge contacts: found by a broad phase and a per-pair manifold, named across steps.

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
    (:func:`narrow_phase`) applies the manifold rule and the margin test: per ordered pair
    the sixteen signed distances, the best face, then, once both orders of a pair are
    known, the reference side, the incident face and the held corners.  Contacts come out
    ordered by ordered pair, then by corner.  Batched in NumPy over ``(4 corners, 4 edges,
    pairs)`` arrays, the rule took some sixty operations whose per-call overhead outweighed
    their arithmetic on scenes of a few dozen bodies.  The broad phase's candidate pairs
    (:func:`candidate_pairs`) are listed in index order, which the contacts' order follows:
    up to :data:`ALL_PAIRS_LIMIT` squares by a compiled loop over all pairs, beyond by a
    tree query (:class:`scipy.spatial.cKDTree`) sorted (:func:`tree_pairs`), so that the
    order does not depend on the tree's traversal; :func:`bounds` and :func:`pairs_within`
    compute the bounding circles and filter the candidates around it.

    Each distance is ``(e_x o_y - e_y o_x) / |e|``, each projection ``(o_x a_x + o_y a_y) /
    |a|``, ``hypot`` the C library's, with numba's default strict IEEE semantics (no
    fast-math, no fused multiply-add): for finite corners the same pairs and contacts in
    the same order with the same distances, bit for bit, as the batched NumPy search they
    replaced (``tests/reference_kernels.py``, checked by ``tests/test_kernels.py``).

Identity across steps
    A contact is named by its point and its edge: the indices of the point and of the
    edge's two corners in the all-points array
    (:meth:`~wuerfel_cvx.step.model.Model.all_points`), one int64 row ``(point, edge_i,
    edge_j)`` of a :data:`ContactIds` array (:meth:`Contacts.ids`).  The same contact found
    again in the next state has the same ids, whatever its place in the list.  The ids are
    plain integers, not packed into one word, so a scene may have any number of points.

    Two things are carried from step to step by it, through one matcher
    (:class:`ContactIndex`):

    * the warm starts (:mod:`wuerfel_cvx.solve.warm_start`): a QP row is named by ``(block,
      contact)``, its block of rows (``velocity``'s rate rows, then its approach rows) and
      its contact's ids, so a row's last multiplier is found as its contact's place in the
      last QP;
    * the Coulomb fixed point's friction impulses
      (:class:`~wuerfel_cvx.friction.coulomb.FrictionMemory`, from one step to the next,
      and from one pass's contacts to the next pass's).

    Matching.  :meth:`ContactIndex.of` puts one set of ids in a hash table (open
    addressing, linear probing, a power-of-two size at least twice the count);
    :meth:`ContactIndex.find` looks another set's ids up, comparing whole ids, so the
    answer is exact whatever the hash: each id's place in the indexed set, or -1.  Time
    O(n + m) for n indexed and m looked-up ids (sorting would be O((n + m) log(n + m)), and
    lexicographic sorting of three columns is several sorts); each is one compiled loop, so
    a small scene pays a call, not a dozen NumPy operations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from .._numba import compiled, running_max
from ..scenes.geometry import FloatArray
from .model import IntArray, Model

#: Lengths closer than this (m) count as equal: two faces' separations (a tie between the
#: bodies goes to the longer face), and a corner's place along a face's line and the
#: face's end (a corner this close to the end is on the face).  The compiled loops compile
#: it in.
TIE_TOLERANCE = 1e-9


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
        return _deepest(self.distance)

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

        The contact's name across steps (the module docstring), in the whole model's
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
    reversed.  Compiled loops over the candidate square pairs of :func:`candidate_pairs`.
    """
    n = model.n_boxes
    centers, bound = bounds(all_points.reshape(-1, 4, 2), reach)
    candidates = (candidate_pairs(centers[:n], 2.0 * float(bound[:n].max()))
                  if n > 1 else np.zeros((0, 2), dtype=np.int64))
    return pairs_within(centers, bound, candidates, n)


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
    if not (isinstance(margin, np.ndarray) and margin.shape == (model.n_bodies,)
            and margin.dtype == np.float64 and margin.flags.c_contiguous):
        margin = np.full(model.n_bodies, margin, dtype=np.float64)
    return _search(model, points, margin)


def _search(model: Model, points: FloatArray, reach: FloatArray) -> Contacts:
    """:func:`body_pairs`, then :func:`narrow_phase`, as contacts.

    Up to :data:`ALL_PAIRS_LIMIT` squares both phases run in one compiled call
    (:func:`_search_all_pairs`, the same loops), so a small scene pays one call.
    """
    corners = model.all_points(points).reshape(-1, 4, 2)
    if model.n_boxes <= ALL_PAIRS_LIMIT:
        return Contacts(*_search_all_pairs(corners, reach, model.n_boxes))
    pairs = body_pairs(model, corners.reshape(-1, 2), reach)
    if len(pairs) == 0:
        return Contacts.empty()
    return Contacts(*_contacts_of(pairs, *narrow_phase(corners, pairs[:, 0], pairs[:, 1],
                                                       reach)))


# ---------------------------------------------------------------------- compiled loops
@compiled
def _deepest(distance: FloatArray) -> float:
    """``max(0.0, -np.min(distance))`` (m), 0 for no distance.

    Python's ``max`` keeps its first argument unless the second is larger, so a NaN (which
    ``np.min`` returns if any distance is NaN) and a zero of either sign give +0.
    """
    lowest = np.inf
    for c in range(distance.shape[0]):
        if distance[c] != distance[c]:
            return 0.0
        lowest = min(lowest, distance[c])
    return -lowest if -lowest > 0.0 else 0.0


ALL_PAIRS_LIMIT = 64
"""Up to this many squares the broad phase checks every pair (a compiled loop) rather than
build a tree: on 20 to 64 squares the loop took 1 to 5 us, the tree query 18 to 22 us."""


@compiled
def _distances(corners: FloatArray, w: int, q: int, out: FloatArray) -> None:
    """``out[k, e]``: corner ``k`` of body ``q`` from edge ``e`` of body ``w`` (m)."""
    for e in range(4):
        f = (e + 1) % 4  # head of edge e: (i, j) = (head, tail) in contact order
        edge_x = corners[w, e, 0] - corners[w, f, 0]
        edge_y = corners[w, e, 1] - corners[w, f, 1]
        length = math.sqrt(edge_x * edge_x + edge_y * edge_y)
        for k in range(4):
            offset_x = corners[q, k, 0] - corners[w, f, 0]
            offset_y = corners[q, k, 1] - corners[w, f, 1]
            out[k, e] = (edge_x * offset_y - edge_y * offset_x) / length


@compiled
def _best_faces(distances: FloatArray) -> tuple[IntArray, FloatArray]:
    """Each ordered pair's face of largest separation, and that separation (m)."""
    n_pairs = distances.shape[0]
    best_face = np.empty(n_pairs, dtype=np.int64)
    best = np.empty(n_pairs)
    for p in range(n_pairs):
        top, top_face = -np.inf, 0
        for e in range(4):
            separation = min(min(distances[p, 0, e], distances[p, 1, e]),
                             min(distances[p, 2, e], distances[p, 3, e]))
            if e == 0 or separation > top:
                top, top_face = separation, e
        best_face[p], best[p] = top_face, top
    return best_face, best


@compiled
def _length(corners: FloatArray, body: int, start: int, end: int) -> float:
    """Length (m) of the segment from corner ``start`` to corner ``end`` of ``body``."""
    x = corners[body, end, 0] - corners[body, start, 0]
    y = corners[body, end, 1] - corners[body, start, 1]
    return math.sqrt(x * x + y * y)


@compiled
def _is_reference(corners: FloatArray, edge_body: IntArray, best_face: IntArray,
                  best: FloatArray) -> np.ndarray:
    """For each ordered pair, whether its edge body holds the pair's reference face."""
    n_pairs = best.shape[0]
    half = n_pairs // 2
    reference = np.empty(n_pairs, dtype=np.bool_)
    for p in range(half):
        r = p + half
        if abs(best[p] - best[r]) <= TIE_TOLERANCE:
            first = (_length(corners, edge_body[p], best_face[p], (best_face[p] + 1) % 4)
                     >= _length(corners, edge_body[r], best_face[r], (best_face[r] + 1) % 4))
        else:
            first = best[p] > best[r]
        reference[p], reference[r] = first, not first
    return reference


@compiled
def _incident_face(corners: FloatArray, w: int, q: int, reference_face: int) -> int:
    """The face of body ``w`` whose outward normal is most anti-parallel to ``q``'s face."""
    g = (reference_face + 1) % 4
    ref_x = corners[q, g, 0] - corners[q, reference_face, 0]
    ref_y = corners[q, g, 1] - corners[q, reference_face, 1]
    ref_length = math.sqrt(ref_x * ref_x + ref_y * ref_y)
    normal_x, normal_y = ref_y / ref_length, -ref_x / ref_length
    lowest, incident = np.inf, 0
    for f in range(4):
        h = (f + 1) % 4
        x = corners[w, h, 0] - corners[w, f, 0]
        y = corners[w, h, 1] - corners[w, f, 1]
        length = math.sqrt(x * x + y * y)
        facing = (y / length) * normal_x + (-x / length) * normal_y
        if f == 0 or facing < lowest:
            lowest, incident = facing, f
    return incident


@compiled
def _narrow_phase(corners: FloatArray, edge_body: IntArray, point_body: IntArray,
                  reach: FloatArray
                  ) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]:
    """Held (pair, corner, edge, distance, clearance) of the ordered pairs, pair-major."""
    n_pairs = edge_body.shape[0]
    half = n_pairs // 2
    distances = np.empty((n_pairs, 4, 4))  # [pair, corner, edge]
    for p in range(n_pairs):
        _distances(corners, edge_body[p], point_body[p], distances[p])
    best_face, best = _best_faces(distances)
    reference = _is_reference(corners, edge_body, best_face, best)
    pair_out = np.empty(4 * n_pairs, dtype=np.int64)
    corner_out = np.empty(4 * n_pairs, dtype=np.int64)
    edge_out = np.empty(4 * n_pairs, dtype=np.int64)
    distance_out = np.empty(4 * n_pairs)
    clearance_out = np.empty(4 * n_pairs)
    count = 0
    for p in range(n_pairs):
        w, q = edge_body[p], point_body[p]
        margin = reach[w] + reach[q]
        reference_face = best_face[p + half if p < half else p - half]
        face = best_face[p] if reference[p] else _incident_face(corners, w, q,
                                                               reference_face)
        end = (face + 1) % 4
        along_x = corners[w, end, 0] - corners[w, face, 0]
        along_y = corners[w, end, 1] - corners[w, face, 1]
        length = math.sqrt(along_x * along_x + along_y * along_y)
        for k in range(4):
            if not (reference[p] or k == reference_face or k == (reference_face + 1) % 4):
                continue
            distance = distances[p, k, face]
            offset_x = corners[q, k, 0] - corners[w, face, 0]
            offset_y = corners[q, k, 1] - corners[w, face, 1]
            place = (offset_x * along_x + offset_y * along_y) / length
            beyond = max(-place, place - length)
            near_end = (distance > 0.0 and beyond <= length
                        and math.hypot(beyond, distance) <= margin)
            if (beyond <= TIE_TOLERANCE or near_end) and distance <= margin:
                pair_out[count], corner_out[count] = p, k
                edge_out[count], distance_out[count] = face, distance
                clearance_out[count] = 0.0
                if beyond > TIE_TOLERANCE:  # as the NumPy reference computed it
                    clearance_out[count] = math.sqrt(beyond * beyond
                                                     + distance * distance) - distance
                count += 1
    return (pair_out[:count], corner_out[:count], edge_out[:count], distance_out[:count],
            clearance_out[:count])


@compiled
def _bounds(corners: FloatArray, reach: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Each body's centre ``(n_bodies, 2)`` (m) and bounding radius plus reach (m)."""
    n_bodies = corners.shape[0]
    centers = np.empty((n_bodies, 2))
    bound = np.empty(n_bodies)
    for b in range(n_bodies):
        for axis in range(2):  # summed corner by corner, as NumPy's reduction over axis 1
            centers[b, axis] = (((corners[b, 0, axis] + corners[b, 1, axis])
                                 + corners[b, 2, axis]) + corners[b, 3, axis]) / 4.0
        radius = 0.0
        for k in range(4):
            x = corners[b, k, 0] - centers[b, 0]
            y = corners[b, k, 1] - centers[b, 1]
            length = math.sqrt(x * x + y * y)
            if k == 0 or length > radius:
                radius = length
        bound[b] = radius + reach[b]
    return centers, bound


@compiled
def _pairs(centers: FloatArray, bound: FloatArray, candidates: IntArray,
           n_boxes: int) -> IntArray:
    """The candidate square pairs within reach, then the square-table pairs, then reversed."""
    n_bodies = centers.shape[0]
    kept = np.empty((candidates.shape[0] + n_boxes * (n_bodies - n_boxes), 2), dtype=np.int64)
    count = 0
    for p in range(candidates.shape[0]):
        a, b = candidates[p, 0], candidates[p, 1]
        x = centers[a, 0] - centers[b, 0]
        y = centers[a, 1] - centers[b, 1]
        if math.sqrt(x * x + y * y) <= bound[a] + bound[b]:
            kept[count, 0], kept[count, 1] = a, b
            count += 1
    for a in range(n_boxes):
        for b in range(n_boxes, n_bodies):
            x = centers[a, 0] - centers[b, 0]
            y = centers[a, 1] - centers[b, 1]
            if math.sqrt(x * x + y * y) <= bound[a] + bound[b]:
                kept[count, 0], kept[count, 1] = a, b
                count += 1
    pairs = np.empty((2 * count, 2), dtype=np.int64)
    for p in range(count):
        pairs[p, 0], pairs[p, 1] = kept[p, 0], kept[p, 1]
        pairs[count + p, 0], pairs[count + p, 1] = kept[p, 1], kept[p, 0]
    return pairs


@compiled
def _all_pairs(centers: FloatArray, radius: float) -> IntArray:
    """Pairs ``i < j`` with ``|c_i - c_j|^2 <= radius^2``, by ``i``, then ``j``.

    Each pair's squared distance against the squared radius, as the tree query tests it.
    """
    n = centers.shape[0]
    found = np.empty((n * (n - 1) // 2, 2), dtype=np.int64)
    limit = radius * radius
    count = 0
    for i in range(n):
        for j in range(i + 1, n):
            x = centers[i, 0] - centers[j, 0]
            y = centers[i, 1] - centers[j, 1]
            if x * x + y * y <= limit:
                found[count, 0], found[count, 1] = i, j
                count += 1
    return found[:count]


@compiled
def _contacts_of(pairs: IntArray, pair_index: IntArray, corner: IntArray, edge_index: IntArray,
                 distance: FloatArray, clearance: FloatArray,
                 ) -> tuple[IntArray, IntArray, IntArray, IntArray, IntArray, FloatArray,
                            FloatArray]:
    """The fields of :class:`Contacts` from the ordered ``pairs`` and the held contacts.

    ``pair_index``, ``corner``, ``edge_index``, ``distance`` and ``clearance`` as
    :func:`narrow_phase` returns them: a held contact's point is corner ``corner`` of the
    point body, its edge ``(edge_index + 1, edge_index)`` of the edge body (contact order).
    """
    count = pair_index.shape[0]
    point, edge_i, edge_j = np.empty(count, np.int64), np.empty(count, np.int64), np.empty(
        count, np.int64)
    point_body, edge_body = np.empty(count, np.int64), np.empty(count, np.int64)
    for c in range(count):
        w, q = pairs[pair_index[c], 0], pairs[pair_index[c], 1]
        point[c] = 4 * q + corner[c]
        edge_i[c] = 4 * w + (edge_index[c] + 1) % 4
        edge_j[c] = 4 * w + edge_index[c]
        point_body[c], edge_body[c] = q, w
    return point, edge_i, edge_j, point_body, edge_body, distance, clearance


@compiled
def _search_all_pairs(corners: FloatArray, reach: FloatArray, n_boxes: int,
                      ) -> tuple[IntArray, IntArray, IntArray, IntArray, IntArray, FloatArray,
                                 FloatArray]:
    """:func:`_search` of up to :data:`ALL_PAIRS_LIMIT` squares in one call.

    The loops of :func:`bounds`, :func:`candidate_pairs` (all pairs within twice the
    largest square bound), :func:`pairs_within`, :func:`narrow_phase` and
    :func:`_contacts_of`, one after another.  The largest bound is NumPy's ``max``: the
    bounds (circumradius plus reach) are not -0 unless a reach is, and a NaN is kept.
    """
    centers, bound = _bounds(corners, reach)
    largest = bound[0] if n_boxes else 0.0
    for b in range(1, n_boxes):
        largest = running_max(largest, bound[b])
    candidates = (_all_pairs(centers[:n_boxes], 2.0 * largest) if n_boxes > 1
                  else np.zeros((0, 2), dtype=np.int64))
    pairs = _pairs(centers, bound, candidates, n_boxes)
    held = _narrow_phase(corners, pairs[:, 0].copy(), pairs[:, 1].copy(), reach)
    return _contacts_of(pairs, *held)


def tree_pairs(centers: FloatArray, radius: float) -> IntArray:
    """Pairs ``(i, j)``, ``i < j``, of ``centers`` (m) within ``radius`` (m), in index order.

    ``cKDTree.query_pairs`` lists them in the order its traversal meets them, which
    depends on the tree; sorted by ``i``, then ``j``, they are in an order of their own.
    """
    found = cKDTree(centers).query_pairs(r=radius, output_type="ndarray")
    return found[np.lexsort((found[:, 1], found[:, 0]))]


def candidate_pairs(centers: FloatArray, radius: float) -> IntArray:
    """:func:`tree_pairs`: the same pairs in the same order.

    Up to :data:`ALL_PAIRS_LIMIT` centres a compiled loop over all pairs lists them
    (``tests/test_kernels.py`` checks it against the tree); beyond, the tree.
    """
    if centers.shape[0] <= ALL_PAIRS_LIMIT:
        return _all_pairs(np.ascontiguousarray(centers, dtype=np.float64), float(radius))
    return tree_pairs(centers, radius)


def bounds(corners: FloatArray, reach: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Body centres ``(n_bodies, 2)`` (m) and bounds ``(n_bodies,)`` (m) of the broad phase.

    The corner mean, and the largest corner distance from it plus ``reach``.
    """
    return _bounds(np.ascontiguousarray(corners, dtype=np.float64),
                   np.ascontiguousarray(reach, dtype=np.float64))


def pairs_within(centers: FloatArray, bound: FloatArray, candidates: IntArray,
                 n_boxes: int) -> IntArray:
    """The ordered pairs of :func:`body_pairs` from the tree's candidates.

    ``candidates`` ``(C, 2)``: square pairs from :func:`candidate_pairs`; squares are bodies
    ``0 .. n_boxes - 1``, tables the rest.  Kept in the candidates' order, then the
    square-table pairs by square, then table; then all of them reversed.
    """
    return _pairs(centers, bound, np.ascontiguousarray(candidates, dtype=np.int64),
                  int(n_boxes))


def narrow_phase(corners: FloatArray, edge_body: IntArray, point_body: IntArray,
                 reach: FloatArray
                 ) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]:
    """Held contacts of the ordered pairs: pair index, corner, edge, distance, clearance (m).

    ``corners`` ``(n_bodies, 4, 2)`` (m, counter-clockwise), ``edge_body`` and
    ``point_body`` ``(P,)`` the ordered pairs of :func:`body_pairs`
    (the second half the first reversed), ``reach`` ``(n_bodies,)`` (m).  The rule and the
    order are those of the module docstring.
    """
    return _narrow_phase(np.ascontiguousarray(corners, dtype=np.float64),
                         np.ascontiguousarray(edge_body, dtype=np.int64),
                         np.ascontiguousarray(point_body, dtype=np.int64),
                         np.ascontiguousarray(reach, dtype=np.float64))


# ---------------------------------------------------------------------- identity across steps
ContactIds = IntArray
"""Contacts' ids ``(n, 3)`` int64: each row a contact's ``(point, edge_i, edge_j)``."""


@compiled
def _slot(ids: IntArray, row: int, mask: int) -> int:
    """Row ``row`` of ``ids``: its first slot in a table of ``mask + 1`` slots (a power of 2).

    Each column is folded to 32 bits, mixed in, and the result multiplied by an odd 31-bit
    constant (a product below 2**63: no overflow) and shifted onto itself.
    """
    hashed = 0
    for column in range(ids.shape[1]):
        value = ids[row, column]
        hashed = ((hashed ^ value ^ (value >> 32)) & 0xFFFFFFFF) * 0x7FEB352D
        hashed ^= hashed >> 29
    return hashed & mask


@compiled
def _table(ids: IntArray, size: int) -> IntArray:
    """A table of ``size`` (a power of 2) slots holding each row's place, -1 where empty."""
    table = np.full(size, -1, dtype=np.int64)
    for row in range(ids.shape[0]):
        slot = _slot(ids, row, size - 1)
        while table[slot] >= 0:
            slot = (slot + 1) & (size - 1)
        table[slot] = row
    return table


@compiled
def _lookup(table: IntArray, ids: IntArray, wanted: IntArray) -> IntArray:
    """Each ``wanted`` row's place in ``ids`` (indexed in ``table``), -1 where it is not."""
    mask = table.shape[0] - 1
    found = np.full(wanted.shape[0], -1, dtype=np.int64)
    for row in range(wanted.shape[0]):
        slot = _slot(wanted, row, mask)
        while table[slot] >= 0:
            held = table[slot]
            same = True
            for column in range(ids.shape[1]):
                if ids[held, column] != wanted[row, column]:
                    same = False
                    break
            if same:
                found[row] = held
                break
            slot = (slot + 1) & mask
    return found


@compiled
def carry_rows(place: IntArray, values: FloatArray, indexed: int, blocks: int,
               out: FloatArray) -> int:
    """Rows of values moved to the contacts found at ``place``, in place; the rows moved.

    ``values`` holds blocks of rows, one row per indexed contact (row ``b * indexed + j``:
    block ``b``, contact ``j``); ``out`` the same blocks for the ``m = len(place)`` contacts
    looked up.  For each of the first ``blocks`` blocks and each contact ``k`` found
    (``place[k] >= 0``), ``out[b * m + k] = values[b * indexed + place[k]]``; other rows
    keep their value.
    """
    count = place.shape[0]
    moved = 0
    for k in range(count):
        if place[k] >= 0:
            for block in range(blocks):
                out[block * count + k] = values[block * indexed + place[k]]
            moved += blocks
    return moved


@dataclass(frozen=True)
class ContactIndex:
    """A set of contacts' ids, indexed to find other contacts' places in it by their ids."""

    ids: ContactIds
    """The indexed ids ``(n, k)`` int64, in their order (distinct, as one state's are)."""
    _table: IntArray
    """The hash table: per slot the place in :attr:`ids` of the id it holds, -1 if none."""

    @classmethod
    def of(cls, ids: NDArray[np.integer]) -> ContactIndex:
        """``ids`` ``(n, k)`` indexed, each row one contact's ids (a repeated row: its first)."""
        held = np.ascontiguousarray(ids, dtype=np.int64)
        if held.ndim != 2:
            raise ValueError(f"ids must be (n, k), got shape {held.shape}")
        size = 1 << max(1, int(2 * held.shape[0] - 1).bit_length())  # >= 2 n
        return cls(held, _table(held, size))

    @classmethod
    def empty(cls) -> ContactIndex:
        """No contacts."""
        return cls.of(np.zeros((0, 3), dtype=np.int64))

    def __len__(self) -> int:
        return int(self.ids.shape[0])

    def find(self, ids: NDArray[np.integer]) -> IntArray:
        """Each row of ``ids`` ``(m, k)``: its place in :attr:`ids`, -1 if it is not there."""
        wanted = np.ascontiguousarray(ids, dtype=np.int64)
        if wanted.ndim != 2 or wanted.shape[1] != self.ids.shape[1]:
            raise ValueError(f"ids must be (m, {self.ids.shape[1]}), got shape {wanted.shape}")
        return _lookup(self._table, self.ids, wanted)

    def carry(self, values: FloatArray, ids: NDArray[np.integer]) -> FloatArray:
        """``values`` (one per indexed contact) moved to the contacts ``ids``, 0 for a new one."""
        place = self.find(ids)
        carried = np.zeros(place.shape[0])
        carry_rows(place, np.asarray(values, dtype=np.float64), len(self), 1, carried)
        return carried
