"""The per-pair contact manifold rule of :mod:`wuerfel_cvx.step.contacts`, one pair at a time.

An independent reference for the batched search: plain loops over body pairs and
corners, :func:`~wuerfel_cvx.scenes.geometry.edge_distances` for the distances and
:func:`~wuerfel_cvx.scenes.geometry.edge_parameter` for a corner's place along a face.
"""

from __future__ import annotations

import math

import numpy as np

from wuerfel_cvx.scenes.geometry import FloatArray, edge_distances, edge_parameter
from wuerfel_cvx.step.contacts import TIE_TOLERANCE

Row = tuple[int, int, int, int, int, float, float]
"""(point, edge_i, edge_j, point_body, edge_body, distance (m), clearance (m)), as in
``Contacts``."""


def outward_normal(polygon: FloatArray, face: int) -> FloatArray:
    """Unit outward normal of face ``face`` (corner ``face`` to ``face + 1``), CCW polygon."""
    d = polygon[(face + 1) % 4] - polygon[face]
    return np.array([d[1], -d[0]]) / np.hypot(d[0], d[1])


def face_length(polygon: FloatArray, face: int) -> float:
    """Length (m) of face ``face`` (corner ``face`` to ``face + 1``)."""
    return float(np.hypot(*(polygon[(face + 1) % 4] - polygon[face])))


def past_end(polygon: FloatArray, face: int, point: FloatArray) -> float:
    """How far (m) ``point``'s projection on the face's line lies beyond the face's ends."""
    tail, head = polygon[face], polygon[(face + 1) % 4]
    length = float(np.hypot(*(head - tail)))
    place = float(edge_parameter(tail, head, point)) * length
    return max(-place, place - length, 0.0)


def clearance(polygon: FloatArray, face: int, point: FloatArray, distance: float) -> float:
    """How much farther (m) ``point`` is from the face (segment) than from its line.

    In the search's arithmetic (projection ``(o . a) / |a|``, ``sqrt(b^2 + d^2) - d``), so
    that the value agrees bit for bit; 0 within :data:`TIE_TOLERANCE` of the face.
    """
    tail, head = polygon[face], polygon[(face + 1) % 4]
    along_x, along_y = float(head[0] - tail[0]), float(head[1] - tail[1])
    offset_x, offset_y = float(point[0] - tail[0]), float(point[1] - tail[1])
    length = math.sqrt(along_x * along_x + along_y * along_y)
    place = (offset_x * along_x + offset_y * along_y) / length
    beyond = max(-place, place - length)
    if beyond <= TIE_TOLERANCE:
        return 0.0
    return math.sqrt(beyond * beyond + distance * distance) - distance


def pair_rows(corners: FloatArray, a: int, b: int, pair_margin: float) -> list[Row]:
    """The rows of the unordered pair ``a < b`` (body indices into ``corners (n, 4, 2)``)."""
    separation_a = edge_distances(corners[b], corners[a]).min(axis=0)  # a's faces
    separation_b = edge_distances(corners[a], corners[b]).min(axis=0)
    face_a, face_b = int(np.argmax(separation_a)), int(np.argmax(separation_b))
    if abs(separation_a.max() - separation_b.max()) <= TIE_TOLERANCE:
        a_holds = face_length(corners[a], face_a) >= face_length(corners[b], face_b)
    else:
        a_holds = separation_a.max() > separation_b.max()
    reference, other, face = (a, b, face_a) if a_holds else (b, a, face_b)
    normal = outward_normal(corners[reference], face)
    incident = int(np.argmin([outward_normal(corners[other], f) @ normal for f in range(4)]))
    rows: list[Row] = []
    for edge_body, point_body, edge, offered in (
            (reference, other, face, range(4)),
            (other, reference, incident, (face, (face + 1) % 4))):
        polygon = corners[edge_body]
        for k in offered:
            point = corners[point_body, k]
            distance = float(edge_distances(point[None, :], polygon)[0, edge])
            beyond = past_end(polygon, edge, point)
            on_face = beyond <= TIE_TOLERANCE or (
                distance > 0.0 and beyond <= face_length(polygon, edge)
                and math.hypot(beyond, distance) <= pair_margin)
            if distance <= pair_margin and on_face:
                rows.append((4 * point_body + k, 4 * edge_body + (edge + 1) % 4,
                             4 * edge_body + edge, point_body, edge_body, distance,
                             clearance(polygon, edge, point, distance)))
    return rows


def manifold_rows(corners: FloatArray, n_boxes: int, pairs: np.ndarray,
                  reach: FloatArray) -> list[Row]:
    """Rows of the ordered ``pairs (P, 2)`` (edge body, point body), in their order.

    ``pairs`` lists each unordered pair twice (either order); within an ordered pair the
    rows come by corner.  ``reach`` ``(n_bodies,)`` (m): a pair's margin is the sum.
    """
    by_order: dict[tuple[int, int], list[Row]] = {}
    for w, b in pairs.tolist():
        if w >= n_boxes and b >= n_boxes:
            continue
        a, c = min(w, b), max(w, b)
        if (a, c) not in by_order:
            by_order[(a, c)] = []
            by_order[(c, a)] = []
            for row in pair_rows(corners, a, c, float(reach[a] + reach[c])):
                by_order[(row[4], row[3])].append(row)
    return [row for w, b in pairs.tolist() for row in sorted(by_order.get((w, b), []))]
