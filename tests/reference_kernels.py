"""The step path's NumPy versions, kept as references for its compiled kernels.

Each function here is the batched NumPy code a stage ran before the compiled kernel
replaced it (the compiled loops in the stage's own module: ``step/contacts.py``,
``formulations/rows.py``, ``formulations/motion.py``, ``formulations/velocity.py``,
``step/criteria.py``, ``solve/residual_kernel.py``); the
product runs the kernels only, and ``tests/test_kernels.py`` checks them against these, bit
for bit.  The KKT check keeps its
general NumPy code in the product (QPs with a coupling cost or upper bounds):
:func:`general_route` hands it a QP the kernel would check.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
from numpy.typing import NDArray

from wuerfel_cvx.formulations.motion import BodyMotion
from wuerfel_cvx.formulations.qp import StepQP
from wuerfel_cvx.formulations.rigid import body_velocities
from wuerfel_cvx.formulations.rows import n_unknown_points, unknown_index
from wuerfel_cvx.scenes.geometry import FloatArray, corner_mean, cross, rot90, side_gradients
from wuerfel_cvx.step.contacts import TIE_TOLERANCE, Contacts, pair_distances, tree_pairs
from wuerfel_cvx.step.criteria import OPEN_GAP_M
from wuerfel_cvx.step.model import IntArray, Model, State

# --------------------------------------------------------------------------------------
# Contact search (wuerfel_cvx.step.contacts, compiled there)
# --------------------------------------------------------------------------------------


def _lengths(vectors: FloatArray) -> FloatArray:
    """Euclidean lengths (m) over the last axis, as ``np.linalg.norm`` computes them."""
    x, y = vectors[..., 0], vectors[..., 1]
    return np.asarray(np.sqrt(x * x + y * y), dtype=np.float64)


def body_pairs(model: Model, all_points: FloatArray, reach: FloatArray) -> IntArray:
    """Ordered (edge body, point body) pairs that may touch, ``(P, 2)``.

    The candidate square pairs from the tree query, sorted (:func:`tree_pairs`), kept
    within reach, then the square-table pairs, then all of them reversed.
    """
    n, t = model.n_boxes, model.n_tables
    corners = all_points.reshape(-1, 4, 2)
    centers = corner_mean(corners)
    radii = _lengths(corners - centers[:, None, :]).max(axis=1)
    bound = radii + reach
    found = [np.zeros((0, 2), dtype=np.int64)]
    if n > 1:
        candidates = tree_pairs(centers[:n], 2.0 * float(bound[:n].max()))
        dist = _lengths(centers[candidates[:, 0]] - centers[candidates[:, 1]])
        found.append(candidates[dist <= bound[candidates[:, 0]] + bound[candidates[:, 1]]])
    if t:
        dist = _lengths(centers[:n, None, :] - centers[None, n:, :])
        close = np.argwhere(dist <= bound[:n, None] + bound[None, n:])
        found.append(close + np.array([0, n]))
    pairs = np.concatenate(found).astype(np.int64, copy=False)
    return np.concatenate([pairs, pairs[:, ::-1]])


def face_normals(corners: FloatArray) -> FloatArray:
    """Unit outward normals ``(n_bodies, 4, 2)`` of faces ``e`` (corner ``e`` to ``e + 1``)."""
    edge = np.roll(corners, -1, axis=1) - corners
    normal = np.stack([edge[..., 1], -edge[..., 0]], axis=-1)
    return np.asarray(normal / _lengths(edge)[..., None], dtype=np.float64)


def reference_sides(distances: FloatArray, face_length: FloatArray
                    ) -> tuple[IntArray, NDArray[np.bool_]]:
    """Each ordered pair's best face and whether its edge body holds the reference face.

    ``distances`` ``(4 corners, 4 edges, P)`` (m) from ``pair_distances``; ``face_length``
    ``(4 edges, P)`` (m) the edge body's face lengths.  The reference order has the larger
    separation, or, within ``TIE_TOLERANCE``, the longer best face (the first half's on
    equal lengths).
    """
    separation = distances.min(axis=0)  # (4 edges, P): the pair's separation along each normal
    best_face = np.asarray(np.argmax(separation, axis=0), dtype=np.int64)
    best = separation.max(axis=0)
    length = np.take_along_axis(face_length, best_face[None, :], axis=0)[0]
    half = best.shape[0] // 2
    tie = np.abs(best[:half] - best[half:]) <= TIE_TOLERANCE
    first_holds = np.where(tie, length[:half] >= length[half:], best[:half] > best[half:])
    return best_face, np.concatenate([first_holds, ~first_holds])


def choose_edges(corners: FloatArray, edge_body: IntArray, point_body: IntArray,
                 distances: FloatArray, pair_margin: FloatArray
                 ) -> tuple[IntArray, NDArray[np.bool_], FloatArray]:
    """Edge index, whether it holds, and how far (m) it projects past the face's end.

    Each ``(4, P)``, per corner of each pair; the manifold rule of ``wuerfel_cvx.step.contacts``.
    """
    n_pairs = edge_body.shape[0]
    half = n_pairs // 2
    lengths = _lengths(np.roll(corners, -1, axis=1) - corners)  # (n_bodies, 4) face lengths
    best_face, is_reference = reference_sides(distances, lengths.T.take(edge_body, axis=1))
    partner = np.concatenate([np.arange(half, n_pairs), np.arange(half)])
    reference_face = best_face[partner]  # the point body's face, where it is the reference
    normals = face_normals(corners)
    reference_normal = normals[point_body, reference_face]  # (P, 2)
    facing = np.einsum("pfi,pi->fp", normals[edge_body], reference_normal)  # (4 faces, P)
    incident = np.asarray(np.argmin(facing, axis=0), dtype=np.int64)
    face = np.where(is_reference, best_face, incident)  # (P,)
    corner = np.arange(4)[:, None]
    offered = is_reference[None, :] | (corner == reference_face[None, :]) | (
        corner == (reference_face[None, :] + 1) % 4)
    start = corners[edge_body, face]  # (P, 2)
    along = corners[edge_body, (face + 1) % 4] - start
    length = _lengths(along)
    offset = corners[point_body].transpose(1, 0, 2) - start[None, :, :]  # (4, P, 2)
    place = (offset[..., 0] * along[:, 0] + offset[..., 1] * along[:, 1]) / length  # (4, P)
    edge = np.broadcast_to(face, (4, n_pairs)).copy()
    distance = np.take_along_axis(distances, edge[:, None, :], axis=1)[:, 0, :]
    beyond = np.maximum(-place, place - length)  # (4, P) m past the nearer end; < 0 within
    within = beyond <= TIE_TOLERANCE
    near_end = ((distance > 0.0) & (beyond <= length)
                & (np.hypot(beyond, distance) <= pair_margin[None, :]))
    return edge, offered & (within | near_end) & (distance <= pair_margin[None, :]), beyond


def clearances(beyond: FloatArray, distance: FloatArray) -> FloatArray:
    """``Contacts.clearance`` (m) of rows ``beyond`` (m) past their faces' ends."""
    return np.where(beyond > TIE_TOLERANCE,
                    np.sqrt(beyond * beyond + distance * distance) - distance, 0.0)


def narrow_phase(corners: FloatArray, edge_body: IntArray, point_body: IntArray,
                 reach: FloatArray
                 ) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]:
    """Held contacts of the ordered pairs: pair index, corner, edge, distance, clearance (m).

    Rows in pair-major order, as ``contacts.narrow_phase`` returns them.
    """
    distances = pair_distances(corners, edge_body, point_body)
    pair_margin = reach[edge_body] + reach[point_body]
    edge, keep, beyond = choose_edges(corners, edge_body, point_body, distances, pair_margin)
    chosen = np.take_along_axis(distances, edge[:, None, :], axis=1)[:, 0, :]  # (4 corners, P)
    pair_index, corner = np.nonzero(keep.T)  # pair-major order
    distance = chosen[corner, pair_index]
    return (pair_index, corner, edge[corner, pair_index], distance,
            clearances(beyond[corner, pair_index], distance))


def find_contacts(model: Model, points: FloatArray, reach: FloatArray) -> Contacts:
    """``contacts.find_contacts`` with a reach ``(n_bodies,)`` (m): both phases, as contacts."""
    all_points = model.all_points(points)
    pairs = body_pairs(model, all_points, reach)
    if len(pairs) == 0:
        return Contacts.empty()
    edge_body, point_body = pairs[:, 0], pairs[:, 1]
    pair_index, corner, edge_index, distance, clearance = narrow_phase(
        all_points.reshape(-1, 4, 2), edge_body, point_body, reach)
    w = edge_body[pair_index]
    return Contacts(point=4 * point_body[pair_index] + corner,
                    edge_i=4 * w + (edge_index + 1) % 4, edge_j=4 * w + edge_index,
                    point_body=point_body[pair_index], edge_body=w, distance=distance,
                    clearance=clearance)


# --------------------------------------------------------------------------------------
# Rows (wuerfel_cvx.formulations.rows, compiled there)
# --------------------------------------------------------------------------------------


def stacked_point_rows(index: np.ndarray, grad: FloatArray, n_points: int) -> sp.csr_array:
    """``rows.stacked_point_rows``: ``index`` ``(R, B)``, ``grad`` ``(R, B, 2)`` to CSR rows.

    Each row's entries sorted by column with a stable argsort; a point twice in a row:
    summed by scipy.
    """
    n_rows = index.shape[0]
    shape = (n_rows, 2 * n_points)
    moving = index >= 0
    keep = np.repeat(moving.ravel(), 2)  # entries in (row, block, axis) order
    cols = (2 * index[:, :, None] + np.arange(2)).reshape(-1)[keep]
    values = grad.reshape(-1)[keep]
    per_row = 2 * moving.sum(axis=1, dtype=np.int64)
    indptr = np.zeros(n_rows + 1, dtype=np.int64)
    np.cumsum(per_row, out=indptr[1:])
    key = np.repeat(np.arange(n_rows, dtype=np.int64), per_row) * shape[1] + cols
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    if np.any(sorted_key[1:] == sorted_key[:-1]):  # a point twice in a row: let scipy sum
        matrix = sp.csr_array((values, cols, indptr), shape=shape)
        matrix.sum_duplicates()
        return matrix
    matrix = sp.csr_array((values[order], cols[order], indptr), shape=shape)
    matrix.has_canonical_format = True  # sorted above, no duplicates
    return matrix


def point_rows(n_rows: int, n_points: int,
               blocks: list[tuple[np.ndarray, FloatArray]]) -> sp.csr_array:
    """``rows.point_rows`` of per-point gradient blocks, by :func:`stacked_point_rows`."""
    if not blocks:
        return sp.csr_array((n_rows, 2 * n_points))
    index = np.stack([np.asarray(point) for point, _ in blocks], axis=1)  # (R, B)
    grad = np.stack([gradient for _, gradient in blocks], axis=1)  # (R, B, 2)
    return stacked_point_rows(index, grad, n_points)


def rod_blocks(model: Model, points: FloatArray) -> tuple[list[tuple[IntArray, FloatArray]],
                                                          FloatArray]:
    """Rod gradient blocks ``(d/l, -d/l)`` with ``d = p_i - p_j``, and ``C/l`` per rod."""
    i, j = model.rods[:, 0], model.rods[:, 1]
    d = points[i] - points[j]
    length = model.rod_lengths[:, None]
    error = 0.5 * (np.sum(d * d, axis=1) - model.rod_lengths**2) / model.rod_lengths
    return [(i, d / length), (j, -d / length)], error


def rod_rows(model: Model, points: FloatArray) -> tuple[sp.csr_array, FloatArray]:
    """``rows.rod_rows``: the rows of :func:`rod_blocks`, and ``C/l``."""
    blocks, error = rod_blocks(model, points)
    return point_rows(len(error), n_unknown_points(model), blocks), error


def side_blocks(all_points: FloatArray, contacts: Contacts,
                model: Model) -> list[tuple[IntArray, FloatArray]]:
    """Exact gradient of ``A / |p_j - p_i|`` blocks for each contact (edge length fixed)."""
    p_i, p_j, p_k = (all_points.take(index, axis=0)
                     for index in (contacts.edge_i, contacts.edge_j, contacts.point))
    g_i, g_j, g_k = side_gradients(p_i, p_j, p_k)
    scale = 1.0 / np.linalg.norm(g_k, axis=1)[:, None]  # |g_k| = |p_j - p_i| (m)
    return [(unknown_index(model, contacts.edge_i), g_i * scale),
            (unknown_index(model, contacts.edge_j), g_j * scale),
            (unknown_index(model, contacts.point), g_k * scale)]


def side_rows(all_points: FloatArray, contacts: Contacts, model: Model) -> sp.csr_array:
    """``rows.side_rows``: the rows of :func:`side_blocks`."""
    return point_rows(len(contacts), n_unknown_points(model),
                      side_blocks(all_points, contacts, model))


def _offsets(points: FloatArray) -> FloatArray:
    corners = points.reshape(-1, 4, 2)
    return np.asarray(corners - corner_mean(corners)[:, None], dtype=np.float64)


def body_rows(corner_rows: sp.csr_array, points: FloatArray) -> sp.csr_array:
    """``rows.body_rows``: canonical corner rows times the corner map, cells summed in order."""
    n_rows = corner_rows.shape[0]
    n_cols = 3 * (corner_rows.shape[1] // 8)
    turned = rot90(_offsets(points)).reshape(-1)  # per corner coordinate (4 n * 2,)
    row = np.repeat(np.arange(n_rows, dtype=np.int64), np.diff(corner_rows.indptr))
    col = corner_rows.indices.astype(np.int64)
    value = corner_rows.data
    body, axis = col // 8, col % 2
    out_row = np.concatenate([row, row])
    out_col = np.concatenate([3 * body + axis, 3 * body + 2])
    out_value = np.concatenate([value * 1.0, value * turned[col]])
    # by (row, column); the sort is stable, so a cell's entries stay in corner-column order
    # (each half of the concatenation is in the row-major order of corner_rows)
    unsorted_key = out_row * n_cols + out_col
    order = np.argsort(unsorted_key, kind="stable")
    key = unsorted_key[order]
    first = np.ones(key.size, dtype=bool)
    first[1:] = key[1:] != key[:-1]
    cell = np.cumsum(first) - 1
    start = np.flatnonzero(first)
    position = np.arange(key.size) - start[cell]
    sums = np.zeros(start.size)
    ordered = out_value[order]
    for k in range(int(position.max(initial=-1)) + 1):
        at = position == k
        sums[cell[at]] += ordered[at]
    indptr = np.zeros(n_rows + 1, dtype=np.int32)
    np.cumsum(np.bincount(key[start] // n_cols, minlength=n_rows), out=indptr[1:])
    columns = (key[start] % n_cols).astype(np.int32)
    matrix = sp.csr_array((sums, columns, indptr), shape=(n_rows, n_cols))
    matrix.has_canonical_format = True  # sorted by column, one entry per cell
    return matrix


# --------------------------------------------------------------------------------------
# Rigid motion (wuerfel_cvx.formulations.motion, compiled there; .rigid, .velocity)
# --------------------------------------------------------------------------------------


def _fit(reference: FloatArray, points: FloatArray, velocities: FloatArray,
         ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Each box's centroid, fitted angle, centre velocity and spin.

    ``reference`` ``(n, 4, 2)`` (m), ``points`` and ``velocities`` ``(4 n, 2)``; see
    ``wuerfel_cvx.formulations.motion``.  Returns ``center (n, 2)``, ``angle (n,)``,
    ``center_velocity (n, 2)`` and ``spin (n,)``.
    """
    corners = points.reshape(-1, 4, 2)
    vel = velocities.reshape(-1, 4, 2)
    center = corner_mean(corners)
    offsets = corners - center[:, None, :]
    angle = np.arctan2(
        np.sum(reference[..., 0] * offsets[..., 1] - reference[..., 1] * offsets[..., 0], axis=1),
        np.sum(reference * offsets, axis=(1, 2)),
    )
    fitted = _rotated(angle, reference)
    center_velocity = corner_mean(vel)
    relative = vel - center_velocity[:, None, :]
    spin = (np.sum(fitted[..., 0] * relative[..., 1] - fitted[..., 1] * relative[..., 0], axis=1)
            / np.sum(fitted * fitted, axis=(1, 2)))
    return center, angle, center_velocity, spin


def _rotated(angles: FloatArray, reference: FloatArray) -> FloatArray:
    """``reference`` ``(n, 4, 2)`` with body ``k`` turned by ``angles[k]`` (rad)."""
    cos, sin = np.cos(angles)[:, None], np.sin(angles)[:, None]
    x, y = reference[..., 0], reference[..., 1]
    turned = np.empty(reference.shape)
    np.subtract(cos * x, sin * y, out=turned[..., 0])
    np.add(sin * x, cos * y, out=turned[..., 1])
    return turned



def rigid_step(reference: FloatArray, points: FloatArray, velocities: FloatArray,
               dt: float) -> State:
    """``motion.rigid_step``: each box moved rigidly by its fitted motion over ``dt`` (s)."""
    center, angle, center_velocity, omega = _fit(reference, points, velocities)
    new_offsets = _rotated(angle + omega * dt, reference)
    new_center = center + dt * center_velocity
    new_points = new_center[:, None, :] + new_offsets
    new_velocities = center_velocity[:, None, :] + omega[:, None, None] * rot90(new_offsets)
    return State(new_points.reshape(-1, 2), new_velocities.reshape(-1, 2))


def corner_velocities(state: State, solution: FloatArray) -> FloatArray:
    """``RigidFormulation.new_velocities``: ``u + omega rot90(r)`` per corner ``(4 n, 2)``."""
    body = solution.reshape(-1, 3)
    turned = rot90(_offsets(state.points))  # (n, 4, 2)
    # u + omega rot90(r), summed as the sparse corner map (8 n x 3 n) times solution would be
    corners = (0.0 + body[:, None, :2]) + turned * body[:, None, 2:]
    return np.asarray(corners.reshape(-1, 2), dtype=np.float64)


def rigid_objective(model: Model, state: State, dt: float) -> tuple[FloatArray, FloatArray]:
    """``rigid.rigid_objective``: weights ``(M, M, I)`` and target ``(u0 + dt g, omega0)``."""
    masses = model.point_masses.reshape(-1, 4)
    inertia = np.sum(masses * np.sum(model.reference_corners**2, axis=2), axis=1)
    centre_velocity, spin = body_velocities(state.points, state.velocities, masses)
    weights = np.column_stack([masses.sum(axis=1), masses.sum(axis=1), inertia]).ravel()
    target = np.column_stack([centre_velocity + dt * model.gravity, spin]).ravel()
    return weights, target


def body_reach(model: Model, state: State, dt: float, contact_margin: float) -> FloatArray:
    """``VelocityFormulation.body_reach``: half the margin plus ``dt`` (fastest corner + dt g)."""
    speeds = np.linalg.norm(state.velocities, axis=1).reshape(-1, 4).max(axis=1)
    reach_squares = 0.5 * contact_margin + dt * (speeds + dt * np.linalg.norm(model.gravity))
    return np.concatenate([reach_squares, np.full(model.n_tables, 0.5 * contact_margin)])


def reaches(model: Model, state: State, solution: FloatArray, dt: float,
            contact_margin: float) -> tuple[FloatArray, FloatArray, bool]:
    """``VelocityFormulation._reached_contacts``'s reach searched, travel and their test."""
    searched = body_reach(model, state, dt, contact_margin)
    moving = State(state.points, solution.reshape(-1, 2)[: model.n_points])
    travel = (body_reach(model, moving, dt, contact_margin)
              - dt * dt * float(np.linalg.norm(model.gravity)))
    return searched, travel, bool(np.all(travel <= searched))


# --------------------------------------------------------------------------------------
# Closest approach (wuerfel_cvx.formulations.velocity and .motion, compiled there)
# --------------------------------------------------------------------------------------
SAMPLES = 16


def body_motion(model: Model, points: FloatArray, velocities: FloatArray) -> BodyMotion:
    """``motion.body_motion``: the boxes fitted by :func:`_fit`, then the tables."""
    center, angle, center_velocity, spin = _fit(model.reference_corners, points, velocities)
    tables = model.table_points.reshape(-1, 4, 2)
    table_center = corner_mean(tables)
    t = tables.shape[0]
    angle = np.concatenate([angle, np.zeros(t)])
    reference = np.concatenate([model.reference_corners, tables - table_center[:, None, :]])
    return BodyMotion(
        center=np.concatenate([center, table_center]), angle=angle,
        velocity=np.concatenate([center_velocity, np.zeros((t, 2))]),
        spin=np.concatenate([spin, np.zeros(t)]), reference=reference,
        fitted=_rotated(angle, reference), n_boxes=model.n_boxes)


def _contact_corners(contacts: Contacts) -> tuple[IntArray, ...]:
    """Each contact's edge body, point body and the corners ``i``, ``j``, ``k`` involved."""
    return (contacts.edge_body, contacts.point_body, contacts.edge_i % 4,
            contacts.edge_j % 4, contacts.point % 4)


def _corners_at(motion: BodyMotion, contacts: Contacts,
                tau: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each contact's edge ends ``p_i``, ``p_j`` and point ``p_k`` (m) at times ``tau``."""
    edge_body, point_body, corner_i, corner_j, corner_k = _contact_corners(contacts)
    shape = np.shape(tau)
    a, b = (np.reshape(body, (-1,) + (1,) * (len(shape) - 1)) for body in (edge_body,
                                                                              point_body))

    def at(body: IntArray, corner: IntArray) -> FloatArray:
        return motion.positions(body, np.reshape(corner, a.shape), tau)

    return at(a, corner_i), at(a, corner_j), at(b, corner_k)


def gaps_at(motion: BodyMotion, contacts: Contacts, tau: FloatArray) -> FloatArray:
    """Signed distances (m) of the contacts' points from their edge lines at times ``tau``.

    ``tau`` (s) is ``(m,)`` or ``(m, K)`` for ``m`` contacts; the result has its shape.
    """
    p_i, p_j, p_k = _corners_at(motion, contacts, tau)
    return _line_distances(p_j - p_i, p_k - p_i)


def _line_distances(edge: FloatArray, offset: FloatArray) -> FloatArray:
    """Signed distances (m) of points at ``offset`` from an edge's start along ``edge``."""
    return np.asarray(cross(edge, offset) / np.hypot(edge[..., 0], edge[..., 1]))


def face_gaps_at(motion: BodyMotion, contacts: Contacts, tau: FloatArray,
                 ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray]:
    """The rows' gaps (m) at times ``tau``, the line distances (m), ``past`` and ``over``.

    :func:`gaps_at`, but a point that starts past its face's end is held off the face (the
    segment) while it is past the end (``past``): ``hypot(beyond, line distance)``;
    ``over``: it started past the end and has moved over the face.
    """
    p_i, p_j, p_k = _corners_at(motion, contacts, tau)
    edge, offset = p_j - p_i, p_k - p_i
    lines = _line_distances(edge, offset)
    none = np.zeros(np.shape(lines), dtype=bool)
    if contacts.clearance is None or not np.any(contacts.clearance > 0.0):
        return lines, lines, none, none
    length = np.hypot(edge[..., 0], edge[..., 1])
    place = (offset[..., 0] * edge[..., 0] + offset[..., 1] * edge[..., 1]) / length
    beyond = np.maximum(-place, place - length)
    started = np.reshape(contacts.clearance > 0.0, (-1,) + (1,) * (np.ndim(tau) - 1))
    past = started & (beyond > 0.0)
    over = started & ~(beyond > 0.0)
    return np.asarray(np.where(past, np.hypot(beyond, lines), lines)), lines, past, over


def ramp_rate(start: FloatArray, dt: float, push_speed: float) -> FloatArray:
    """The ramp's rate ``(min(0, phi_0 + dt u) - phi_0) / dt`` (m/s) from start gaps (m)."""
    return np.asarray((np.minimum(0.0, start + dt * push_speed) - start) / dt)


def ramp_margins(motion: BodyMotion, contacts: Contacts, tau: FloatArray, dt: float,
                 push_speed: float, starts: tuple[FloatArray, FloatArray] | None = None,
                 ) -> tuple[FloatArray, np.ndarray, tuple[FloatArray, FloatArray]]:
    """``psi`` (m) at ``tau`` ``(m, K)``, whether it is the line's, the start gaps and lines.

    The gap above its ramp; for a point that started past its face's end, the line distance
    above the line's ramp once over the face, or where its gap falls below the face's ramp.
    ``starts``: the start gaps and line distances (m); ``tau[:, 0]`` is 0 where ``None``.
    """
    gaps, lines, past, over = face_gaps_at(motion, contacts, tau)
    start, line_start = (gaps[:, 0], lines[:, 0]) if starts is None else starts
    face = gaps - start[:, None] - ramp_rate(start, dt, push_speed)[:, None] * tau
    line = (lines - line_start[:, None]
            - ramp_rate(line_start, dt, push_speed)[:, None] * tau)
    on_line = over | (past & ~(face >= 0.0))
    return np.asarray(np.where(on_line, line, face)), on_line, (start, line_start)


def closest_approach(model: Model, points: FloatArray, contacts: Contacts, about: FloatArray,
                     dt: float, push_speed: float,
                     ) -> tuple[BodyMotion, FloatArray, FloatArray, FloatArray, FloatArray,
                                float]:
    """``velocity.closest_approach``: the motion, ``tau*``, ``psi(tau*)``, rates, violation.

    The rates (m/s): the rate rows' right-hand sides, the closest-approach rows' caps.
    """
    motion = body_motion(model, points, about.reshape(-1, 2)[: model.n_points])
    m = len(contacts)
    if m == 0:
        return motion, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), 0.0
    grid = np.linspace(0.0, dt, SAMPLES + 1)
    margin, on_line, starts = ramp_margins(motion, contacts,
                                           np.broadcast_to(grid, (m, SAMPLES + 1)), dt,
                                           push_speed)
    rate = ramp_rate(starts[0], dt, push_speed)
    line_rate = ramp_rate(starts[1], dt, push_speed)
    mean_rate = np.empty_like(margin)
    mean_rate[:, 1:] = margin[:, 1:] / grid[1:]
    mean_rate[:, 0] = 2.0 * mean_rate[:, 1] - mean_rate[:, 2]  # for the parabola only
    best = 1 + np.argmin(mean_rate[:, 1:], axis=1)
    inner = np.minimum(best, SAMPLES - 1)
    rows = np.arange(m)
    left, mid, right = (mean_rate[rows, inner + shift] for shift in (-1, 0, 1))
    curvature = left - 2.0 * mid + right
    shift = np.where(curvature > 0.0, 0.5 * (left - right) / np.where(curvature > 0.0,
                                                                      curvature, 1.0), 0.0)
    refined = np.clip((inner + np.clip(shift, -1.0, 1.0)) * dt / SAMPLES, dt / SAMPLES, dt)
    refined_margin, refined_line, _ = ramp_margins(motion, contacts, refined[:, None], dt,
                                                   push_speed, starts)
    refined_margin, refined_line = refined_margin[:, 0], refined_line[:, 0]
    sampled_tau, sampled_margin = grid[best], margin[rows, best]
    take = refined_margin / refined < mean_rate[rows, best]
    violation = float(max(0.0, -np.min(margin), -np.min(refined_margin)))
    closest_line = np.where(take, refined_line, on_line[rows, best])
    return (motion, np.where(take, refined, sampled_tau),
            np.where(take, refined_margin, sampled_margin),
            np.where(on_line[:, 1], line_rate, rate), np.where(closest_line, line_rate, rate),
            violation)


def rows_along(model: Model, contacts: Contacts, motion: BodyMotion, about: FloatArray,
               closest: FloatArray, margin: FloatArray, rate: FloatArray,
               closest_rate: FloatArray) -> tuple[sp.csr_array, FloatArray]:
    """``velocity.rows_along``: the rate rows, then the closest-approach rows, and ``h``."""
    m = len(contacts)
    corners = tuple(np.concatenate([values, values]) for values in _contact_corners(contacts))
    blocks = _approach_blocks(motion, corners, np.concatenate([np.zeros(m), closest]))
    matrix = point_rows(2 * m, n_unknown_points(model), blocks)
    lifted = matrix[m:] @ about - margin / closest
    return matrix, np.concatenate([rate, np.minimum(lifted, closest_rate)])


def _approach_blocks(motion: BodyMotion, corners: tuple[IntArray, ...],
                     tau: FloatArray) -> list[tuple[IntArray, FloatArray]]:
    """Blocks of ``d phi(tau; v) / d v / tau`` over the corners of both bodies of each row."""
    edge_body, point_body, corner_i, corner_j, corner_k = corners
    ends = ((edge_body, corner_i), (edge_body, corner_j), (point_body, corner_k))
    o_i, o_j, o_k = (motion.offsets(body, corner, tau) for body, corner in ends)
    p_i, p_j, p_k = (motion.center[body] + tau[:, None] * motion.velocity[body] + offset
                     for (body, _), offset in zip(ends, (o_i, o_j, o_k), strict=True))
    g_i, g_j, g_k = side_gradients(p_i, p_j, p_k)
    scale = 1.0 / np.linalg.norm(g_k, axis=1)[:, None]  # |g_k| = edge length (m)
    g_i, g_j, g_k = g_i * scale, g_j * scale, g_k * scale
    edge_push = g_i + g_j
    edge_turn = np.sum(g_i * rot90(o_i) + g_j * rot90(o_j), axis=1)
    point_turn = np.sum(g_k * rot90(o_k), axis=1)
    return (_approach_body_blocks(motion, edge_body, edge_push, edge_turn)
            + _approach_body_blocks(motion, point_body, g_k, point_turn))


def _approach_body_blocks(motion: BodyMotion, body: IntArray, push: FloatArray,
                          turn: FloatArray) -> list[tuple[IntArray, FloatArray]]:
    """Four blocks (one per corner of ``body``): ``push / 4 + turn rot90(f_q) / S``."""
    fitted = motion.fitted[body]  # (m, 4, 2)
    weight = turn / np.sum(fitted * fitted, axis=(1, 2))
    coefficients = 0.25 * push[:, None, :] + weight[:, None, None] * rot90(fitted)
    index = np.where((body < motion.n_boxes)[:, None], 4 * body[:, None] + np.arange(4), -1)
    return [(index[:, corner], coefficients[:, corner]) for corner in range(4)]


# --------------------------------------------------------------------------------------
# KKT check (wuerfel_cvx.solve.paths; compiled: wuerfel_cvx.solve.residual_kernel)
# --------------------------------------------------------------------------------------


def general_route(qp: StepQP) -> StepQP:
    """``qp`` with every upper bound ``+inf``: the same QP, checked by the general NumPy code.

    ``solve.kkt_residuals`` and ``solve._checked_scales`` give a QP with ``ineq_upper``
    (even one without a finite entry) to their general NumPy code, and one without to the
    compiled loop.
    """
    return dataclasses.replace(qp, ineq_upper=np.full(qp.n_inequalities, np.inf))


# --------------------------------------------------------------------------------------
# Polish (wuerfel_cvx.solve.kkt; compiled in _sparse.py and solve/residual_kernel.py)
# --------------------------------------------------------------------------------------


def guess_active_set(qp: StepQP, x: FloatArray, ineq_dual: FloatArray, primal_scale: float,
                     dual_scale: float, margin: float) -> tuple[IntArray, IntArray]:
    """The rows tight on their lower and on their upper bounds, by ``guess_active_set``'s rule."""
    lhs = qp.ineq_matrix @ x
    weight = ineq_dual / (margin * dual_scale)
    lower_tight = weight > (lhs - qp.ineq_rhs) / primal_scale
    upper_tight = np.zeros_like(lower_tight)
    rows = qp.upper_rows
    if rows.size:
        assert qp.ineq_upper is not None
        upper_tight[rows] = -weight[rows] > (qp.ineq_upper[rows] - lhs[rows]) / primal_scale
        both = lower_tight & upper_tight
        lower_tight[both] = ineq_dual[both] >= 0.0
        upper_tight[both] = ~lower_tight[both]
    return (np.flatnonzero(lower_tight).astype(np.int64),
            np.flatnonzero(upper_tight).astype(np.int64))


def repaired(qp: StepQP, tight_lower: IntArray, tight_upper: IntArray, x: FloatArray,
             z: FloatArray, dual_tolerance: float, primal_tolerance: float
             ) -> tuple[IntArray, IntArray] | None:
    """An active set corrected for the point ``(x, z)`` solved on it (``kkt._repaired``)."""
    lhs = qp.ineq_matrix @ x
    lower = np.zeros(qp.n_inequalities, dtype=bool)
    upper = np.zeros(qp.n_inequalities, dtype=bool)
    lower[tight_lower], upper[tight_upper] = True, True
    wrong_lower = lower & (z < -dual_tolerance)
    wrong_upper = upper & (z > dual_tolerance)
    violated_lower = ~lower & ((lhs - qp.ineq_rhs) < -primal_tolerance)
    violated_upper = np.zeros_like(upper)
    rows = qp.upper_rows
    if rows.size:
        assert qp.ineq_upper is not None
        violated_upper[rows] = ~upper[rows] & ((qp.ineq_upper[rows] - lhs[rows])
                                               < -primal_tolerance)
    if not (wrong_lower.any() or wrong_upper.any() or violated_lower.any()
            or violated_upper.any()):
        return None
    lower = (lower & ~wrong_lower) | violated_lower
    upper = (upper & ~wrong_upper) | violated_upper
    return np.flatnonzero(lower).astype(np.int64), np.flatnonzero(upper).astype(np.int64)


def _power_of_two(values: FloatArray) -> FloatArray:
    return np.asarray(np.exp2(np.round(np.log2(values))), dtype=np.float64)


def equilibration(matrix: sp.csc_matrix, n: int) -> FloatArray:
    """The power-of-two scales of a reduced KKT matrix (``_sparse.equilibration``)."""
    size = matrix.shape[0]
    column = np.repeat(np.arange(size), np.diff(matrix.indptr))
    scale = np.ones(size)
    on_diagonal = (matrix.indices == column) & (column < n) & (matrix.data > 0.0)
    scale[column[on_diagonal]] = _power_of_two(1.0 / np.sqrt(matrix.data[on_diagonal]))
    coupling = (column >= n) & (matrix.indices < n)
    largest = np.zeros(size)
    np.maximum.at(largest, column[coupling],
                  np.abs(matrix.data[coupling]) * scale[matrix.indices[coupling]])
    rows = np.flatnonzero(largest > 0.0)
    scale[rows] = _power_of_two(1.0 / largest[rows])
    return scale


def scaled(matrix: sp.csc_matrix, scale: FloatArray) -> FloatArray:
    """The entries of ``S matrix S`` (``kkt._scaled``)."""
    column = np.repeat(np.arange(matrix.shape[1]), np.diff(matrix.indptr))
    return np.asarray(matrix.data * scale[matrix.indices] * scale[column], dtype=np.float64)


def regularisation(matrix: sp.csc_matrix, n: int, regularisation: float
                   ) -> tuple[IntArray, FloatArray]:
    """The elimination order and the shifts of ``_sparse.equilibrated_solution`` (own order).

    The new position of each index, and the shifts in the new order.
    """
    size = matrix.shape[0]
    column = np.repeat(np.arange(size), np.diff(matrix.indptr))
    diagonal = np.flatnonzero(matrix.indices == column)
    hessian_scale = float(np.max(np.abs(matrix.data[diagonal[:n]]))) if n else 1.0
    hessian_scale = hessian_scale or 1.0
    coupling = (column < n) & (matrix.indices >= n)
    row_scale = float(np.max(np.abs(matrix.data[coupling]))) if coupling.any() else 1.0
    new_of_old = np.empty(size, dtype=np.int64)
    new_of_old[n:] = np.arange(size - n)
    new_of_old[np.arange(n)] = np.arange(size - n, size)
    shift = np.full(size, -regularisation * row_scale**2 / hessian_scale)
    shift[size - n:] = regularisation * hessian_scale
    return new_of_old, shift


def refined(matrix: sp.csc_matrix, factor: tuple[IntArray, IntArray, FloatArray, FloatArray],
            new_of_old: IntArray, rhs: FloatArray, point: FloatArray, sweeps: int,
            ldl_solve: object) -> FloatArray:
    """``_sparse.refined`` as it was, a new array per sweep (plain Python loops)."""
    size = rhs.shape[0]
    best, best_norm = point, np.inf
    for _ in range(sweeps):
        residual = rhs.copy()
        for column in range(size):
            for k in range(matrix.indptr[column], matrix.indptr[column + 1]):
                residual[matrix.indices[k]] -= matrix.data[k] * point[column]
        norm = 0.0
        for value in np.abs(residual):
            if value != value:
                norm = np.nan
                break
            norm = max(norm, float(value))
        if not norm < best_norm:
            break
        best, best_norm = point, norm
        if norm == 0.0:
            break
        point = point + ldl_solve(*factor, new_of_old, residual)  # type: ignore[operator]
    return best


# --------------------------------------------------------------------------------------
# The physical check (wuerfel_cvx.step.criteria, compiled there)
# --------------------------------------------------------------------------------------


def gaps_after(all_points: FloatArray, contacts: Contacts) -> FloatArray:
    """Signed distance (m) of each contact's point from its edge line at ``all_points``."""
    p_i, p_j, p_k = (all_points[index] for index in (contacts.edge_i, contacts.edge_j,
                                                     contacts.point))
    edge = p_j - p_i
    return np.asarray(cross(edge, p_k - p_i) / np.linalg.norm(edge, axis=1), dtype=np.float64)


def row_pushes(qp: StepQP, x: FloatArray, ineq_dual: FloatArray, impulse_per_multiplier: float,
               gap_per_slack: float) -> dict[str, float]:
    """``criteria.row_pushes``: the largest impulse on an open row, the largest gap x impulse."""
    lhs = qp.ineq_matrix @ x
    slack = lhs - qp.ineq_rhs
    if qp.upper_rows.size:
        assert qp.ineq_upper is not None
        slack = np.where(ineq_dual < 0.0, qp.ineq_upper - lhs, slack)
    impulse = np.abs(ineq_dual) * impulse_per_multiplier
    gap = np.maximum(slack, 0.0) * gap_per_slack
    open_rows = gap > OPEN_GAP_M
    return {"push_at_distance_Ns": float(impulse[open_rows].max()) if open_rows.any() else 0.0,
            "push_gap_product_Nsm": float(np.max(impulse * gap))}


def normal_impulses(count: int, ineq_dual: FloatArray,
                    impulse_per_multiplier: float) -> FloatArray:
    """``criteria.normal_impulses``: the multipliers of each contact's rows, summed (N s)."""
    rows = np.arange(ineq_dual.shape[0]) % max(count, 1)
    return np.asarray(impulse_per_multiplier * np.bincount(rows, weights=ineq_dual,
                                                           minlength=count), dtype=np.float64)


def signorini(all_points: FloatArray, contacts: Contacts, normal: FloatArray) -> float:
    """``criteria.contact_criteria``'s ``signorini_violation_Nsm``: max ``|gap| lambda_n``."""
    return float(np.max(np.abs(gaps_after(all_points, contacts)) * np.maximum(normal, 0.0)))


def fastest_speed(velocities: FloatArray) -> float:
    """``criteria.push_bound``'s largest corner speed (m/s), 0 for none."""
    return float(np.max(np.linalg.norm(velocities, axis=1))) if velocities.size else 0.0


def deepest_penetration(contacts: Contacts) -> float:
    """``Contacts.deepest_penetration``: the deepest point behind its edge's line (m), or 0."""
    return 0.0 if len(contacts) == 0 else float(max(0.0, -np.min(contacts.distance)))


def finite(state: State) -> bool:
    """The simulation's check of a new state: every coordinate finite."""
    return bool(np.isfinite(state.points).all() and np.isfinite(state.velocities).all())
