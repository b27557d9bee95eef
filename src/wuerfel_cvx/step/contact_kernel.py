"""The contact search as compiled loops (numba).

Batched in NumPy over ``(4 corners, 4 edges, pairs)`` arrays, the manifold rule of
:mod:`wuerfel_cvx.step.contacts` takes some sixty operations whose per-call overhead outweighs
their arithmetic on scenes of a few dozen bodies.  :func:`narrow_phase` here runs
it over the pairs as one loop compiled by numba: per ordered pair the sixteen signed
distances, the best face, then, once both orders of a pair are known, the reference side,
the incident face and the held corners.  The broad phase's candidate pairs
(:func:`candidate_pairs`) are listed in index order, which the contacts' order follows: up
to :data:`ALL_PAIRS_LIMIT` squares by a compiled loop over all pairs, beyond by a tree query
(:class:`scipy.spatial.cKDTree`) sorted (:func:`tree_pairs`), so that the order does not
depend on the tree's traversal; :func:`bounds` and :func:`pairs_within` compute the bounding
circles and filter the candidates around it.

Each distance is ``(e_x o_y - e_y o_x) / |e|``, each projection ``(o_x a_x + o_y a_y) /
|a|``, ``hypot`` the C library's, with numba's default strict IEEE semantics (no fast-math,
no fused multiply-add): for finite corners the same pairs and contacts in the same order
with the same distances, bit for bit, as the batched NumPy search it replaced
(``tests/reference_kernels.py``, checked by ``tests/test_kernels.py``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .._numba import compiled
from ..scenes.geometry import FloatArray
from .model import IntArray

#: Lengths closer than this (m) count as equal in the manifold rule (see
#: :data:`wuerfel_cvx.step.contacts.TIE_TOLERANCE`, which is this number); the kernel compiles
#: it in.
TIE_TOLERANCE = 1e-9

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
                if beyond > TIE_TOLERANCE:  # as contacts.clearances computes it
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
    """The ordered pairs of :func:`wuerfel_cvx.step.contacts.body_pairs` from the tree's candidates.

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
    ``point_body`` ``(P,)`` the ordered pairs of :func:`~wuerfel_cvx.step.contacts.body_pairs`
    (the second half the first reversed), ``reach`` ``(n_bodies,)`` (m).  The rule and the
    order are those of the module docstring of :mod:`wuerfel_cvx.step.contacts`.
    """
    return _narrow_phase(np.ascontiguousarray(corners, dtype=np.float64),
                         np.ascontiguousarray(edge_body, dtype=np.int64),
                         np.ascontiguousarray(point_body, dtype=np.int64),
                         np.ascontiguousarray(reach, dtype=np.float64))
