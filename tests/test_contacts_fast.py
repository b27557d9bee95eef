"""The contact search and row assembly equal the per-pair versions of before vectorisation.

The old implementations are kept below verbatim as oracles (from ``contacts.py``,
``formulations/rows.py`` and ``formulations/qp.py`` before vectorisation), except that the
contact search's oracle applies the current per-pair manifold rule one pair at a time and
takes the broad phase's pairs by index, as the search now does.  The product's search and
rows (compiled loops since; their batched NumPy versions are ``tests/reference_kernels.py``)
must return the same contacts in the same order with bit-identical distances, and the same
sparse matrices, so that trajectories stay bit-for-bit comparable.
"""

from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import cKDTree

from manifold_oracle import manifold_rows
from reference_kernels import rod_blocks
from wuerfel_cvx import Scene, simulate
from wuerfel_cvx import formulations as formulations_package
from wuerfel_cvx.formulations import get_formulation, step_qp
from wuerfel_cvx.formulations import rows as new_rows
from wuerfel_cvx.formulations import seed as seed_module
from wuerfel_cvx.formulations import velocity as velocity_module
from wuerfel_cvx.formulations.rows import (
    held_table_blocks,
    n_unknown_points,
    seed_side_blocks,
    unknown_index,
)
from wuerfel_cvx.formulations.velocity import VelocityFormulation
from wuerfel_cvx.scenes.geometry import FloatArray, side_gradients, square_corners
from wuerfel_cvx.scenes.scene import Square, Table
from wuerfel_cvx.step import contacts as new_contacts
from wuerfel_cvx.step import simulation as simulation_module
from wuerfel_cvx.step.contacts import Contacts
from wuerfel_cvx.step.metrics import deepest_penetration
from wuerfel_cvx.step.model import IntArray, Model, State

pytestmark = pytest.mark.integration

# --------------------------------------------------------------------------------------
# Oracles: the implementations before vectorisation, verbatim.
# --------------------------------------------------------------------------------------


def body_pairs(model: Model, all_points: FloatArray, reach: FloatArray) -> IntArray:
    """Ordered (edge body, point body) pairs that may touch, ``(P, 2)``.

    ``reach`` ``(n_bodies,)`` (m) is how far beyond its circumcircle each body must be
    looked for.  Table-table pairs are never returned.
    """
    n, t = model.n_boxes, model.n_tables
    corners = all_points.reshape(-1, 4, 2)
    centers = corners.mean(axis=1)
    radii = np.linalg.norm(corners - centers[:, None, :], axis=2).max(axis=1)
    bound = radii + reach
    unordered: list[tuple[int, int]] = []
    if n > 1:
        tree = cKDTree(centers[:n])
        candidates = tree.query_pairs(r=2.0 * float(bound[:n].max()), output_type="ndarray")
        # by index, not in the tree's traversal order (changed with the compiled broad phase)
        candidates = candidates[np.lexsort((candidates[:, 1], candidates[:, 0]))]
        if len(candidates):
            dist = np.linalg.norm(centers[candidates[:, 0]] - centers[candidates[:, 1]], axis=1)
            keep = dist <= bound[candidates[:, 0]] + bound[candidates[:, 1]]
            unordered.extend(map(tuple, candidates[keep]))
    if t:
        dist = np.linalg.norm(centers[:n, None, :] - centers[None, n:, :], axis=2)
        close = np.argwhere(dist <= bound[:n, None] + bound[None, n:])
        unordered.extend((int(a), int(n + b)) for a, b in close)
    if not unordered:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = np.array(unordered, dtype=np.int64)
    return np.concatenate([pairs, pairs[:, ::-1]])


def find_contacts(
    model: Model, points: FloatArray, margin: FloatArray | float
) -> Contacts:
    """Point-edge contacts whose signed distance is at most ``margin`` (m).

    The broad phase above, then the manifold rule pair by pair (``manifold_oracle``): the
    batched search replaced a per-pair loop, and its rule later replaced the per-corner
    largest-distance edge; this oracle follows the current rule in the old loop form.
    """
    all_points = model.all_points(points)
    reach = np.broadcast_to(np.asarray(margin, dtype=np.float64), (model.n_bodies,))
    pairs = body_pairs(model, all_points, reach)
    rows = manifold_rows(all_points.reshape(-1, 4, 2), model.n_boxes, pairs, reach)
    if not rows:
        return Contacts.empty()
    columns = list(zip(*rows, strict=True))
    return Contacts(*(np.array(column, dtype=np.int64) for column in columns[:5]),
                    distance=np.array(columns[5], dtype=np.float64),
                    clearance=np.array(columns[6], dtype=np.float64))


def side_blocks(all_points: FloatArray, contacts: Contacts,
                model: Model) -> list[tuple[IntArray, FloatArray]]:
    """Exact gradient of ``A / |p_j - p_i|`` blocks for each contact (edge length fixed).

    dA/dp_i = rot90(p_k - p_j), dA/dp_j = rot90(p_i - p_k), dA/dp_k = rot90(p_j - p_i).
    """
    p_i, p_j, p_k = (all_points[contacts.edge_i], all_points[contacts.edge_j],
                     all_points[contacts.point])
    g_i, g_j, g_k = side_gradients(p_i, p_j, p_k)
    scale = 1.0 / np.linalg.norm(p_j - p_i, axis=1)[:, None]
    return [(unknown_index(model, contacts.edge_i), g_i * scale),
            (unknown_index(model, contacts.edge_j), g_j * scale),
            (unknown_index(model, contacts.point), g_k * scale)]


def point_rows(
    n_rows: int,
    n_points: int,
    blocks: list[tuple[np.ndarray, FloatArray]],
) -> sp.csr_array:
    """Assemble a sparse matrix from per-point gradient blocks.

    Each block is ``(point_index (R,), gradient (R, 2))`` for rows ``0..R-1``; a point
    index ``< 0`` (a fixed point) contributes nothing.  Columns are ``2 point + axis``.
    """
    rows, cols, vals = [], [], []
    for index, grad in blocks:
        row = np.arange(n_rows)
        moving = index >= 0
        for axis in (0, 1):
            rows.append(row[moving])
            cols.append(2 * index[moving] + axis)
            vals.append(grad[moving, axis])
    if not rows:
        return sp.csr_array((n_rows, 2 * n_points))
    return sp.csr_array(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
        shape=(n_rows, 2 * n_points),
    )


def old_deepest_penetration(model: Model, points: FloatArray) -> float:
    """``metrics.deepest_penetration`` before vectorisation, on the old search."""
    contacts = find_contacts(model, points, 0.0)
    if len(contacts) == 0:
        return 0.0
    return float(max(0.0, -np.min(contacts.distance)))


# --------------------------------------------------------------------------------------
# States
# --------------------------------------------------------------------------------------

FIELDS = ("point", "edge_i", "edge_j", "point_body", "edge_body", "distance", "clearance")
LIBRARY = {  # scene: steps of simulate after which the state is checked
    "stack-10": (0, 50),
    "pyramid-4": (0, 50),
    "rain-20": (0, 50, 100, 150),
    "overlap-recovery": (0, 1, 5, 50),
    "heavy-on-light-100": (0, 50),
    "edge-end-landing": (0, 40, 50),
    "two-corner-landing": (0, 40, 50),
    "wall-contact": (0, 30, 50),
}


@cache
def library_states(name: str) -> tuple[Model, tuple[State, ...]]:
    scene = Scene.named(name)
    steps = LIBRARY[name]
    traj = simulate(scene, dt=0.01, steps=max(steps))
    states = tuple(State(traj.points[k], traj.velocities[k]) for k in steps)
    return Model.from_scene(scene), states


def random_model(n_squares: int, rng: np.random.Generator, table_mass: float | None = None,
                 n_tables: int = 3) -> Model:
    """A model with ``n_squares`` unit squares and random tables (positions come later)."""
    squares = tuple(Square(center=(3.0 * k, 1000.0)) for k in range(n_squares))
    tables = tuple(Table(center=tuple(rng.uniform(-3, 3, size=2)),
                         size=tuple(rng.uniform(0.5, 6, size=2)), angle=float(rng.uniform(-1, 1)))
                   for _ in range(n_tables))
    return Model.from_scene(Scene("random", squares, tables, allow_overlap=True),
                            table_mass=table_mass)


def random_points(n_squares: int, rng: np.random.Generator, spread: float) -> FloatArray:
    """Corners of squares of random size and angle, centres in a box: many overlaps."""
    corners = [square_corners(rng.uniform(-spread, spread, size=2), rng.uniform(0.3, 1.5),
                              rng.uniform(-math.pi, math.pi)) for _ in range(n_squares)]
    return np.concatenate(corners)


def grid_points(n_squares: int, rng: np.random.Generator) -> FloatArray:
    """Axis-aligned unit squares on a half-unit grid: exact corner-on-corner ties."""
    cells = rng.choice(36, size=n_squares, replace=False)
    centers = np.stack([0.5 * (cells % 6) + 0.5, 0.5 * (cells // 6)], axis=1)
    return np.concatenate([square_corners(c, 1.0, 0.0) for c in centers])


# --------------------------------------------------------------------------------------
# Comparisons
# --------------------------------------------------------------------------------------


def assert_same_contacts(new: Contacts, old: Contacts) -> None:
    for name in FIELDS:
        a, b = getattr(new, name), getattr(old, name)
        if a is None or b is None:  # a clearance not set: 0 for every row, on both sides
            assert a is None and b is None, name
            continue
        assert a.dtype == b.dtype, name
        assert a.shape == b.shape, name
        assert np.array_equal(a, b), name  # same rows, same order, bit-identical


def assert_same_matrix(new: sp.csr_array, old: sp.csr_array) -> None:
    assert new.shape == old.shape
    assert new.has_canonical_format and old.has_canonical_format
    assert np.array_equal(new.indptr, old.indptr)
    assert np.array_equal(new.indices, old.indices)
    assert new.data.dtype == old.data.dtype
    assert np.array_equal(new.data, old.data)


def margins(model: Model, state: State, rng: np.random.Generator) -> list[FloatArray | float]:
    """Scalar margins, the velocity formulation's per-body reach, random per-body values."""
    reach = VelocityFormulation().body_reach(model, state, 0.01)
    return [0.0, 1e-3, 0.01, 0.05, 0.3, reach, rng.uniform(0.0, 0.2, size=model.n_bodies)]


def check_everything(model: Model, state: State, rng: np.random.Generator) -> int:
    """All margins: same contacts; for the velocity reach: same side rows.  Returns count."""
    found = 0
    for margin in margins(model, state, rng):
        new = new_contacts.find_contacts(model, state.points, margin)
        old = find_contacts(model, state.points, margin)
        assert_same_contacts(new, old)
        found += len(new)
    assert deepest_penetration(model, state.points) == old_deepest_penetration(
        model, state.points)
    contacts = find_contacts(model, state.points, margins(model, state, rng)[5])
    all_points = model.all_points(state.points)
    n_unknown = n_unknown_points(model)
    assert_same_matrix(new_rows.side_rows(all_points, contacts, model),
                       point_rows(len(contacts), n_unknown, side_blocks(all_points, contacts,
                                                                         model)))
    seed_blocks = seed_side_blocks(all_points, contacts, model)
    assert_same_matrix(new_rows.point_rows(len(contacts), n_unknown, seed_blocks),
                       point_rows(len(contacts), n_unknown, seed_blocks))
    rods, _ = rod_blocks(model, state.points)
    assert_same_matrix(new_rows.rod_rows(model, state.points)[0],
                       point_rows(len(model.rods), n_unknown, rods))
    held = held_table_blocks(model)
    if held:
        assert_same_matrix(new_rows.point_rows(len(held[0][0]), n_unknown, held),
                           point_rows(len(held[0][0]), n_unknown, held))
    return found


# --------------------------------------------------------------------------------------
# Tests
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_library_states_give_the_same_contacts_and_rows(name: str) -> None:
    model, states = library_states(name)
    rng = np.random.default_rng(11)
    found = 0
    for state in states:
        found += check_everything(model, state, rng)
        heavy = Model.from_scene(model.scene, table_mass=1e3)  # tables become unknowns
        found += check_everything(heavy, state, rng)
    assert found > 0


@pytest.mark.parametrize("seed", range(12))
def test_random_overlapping_states_give_the_same_contacts_and_rows(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_squares = int(rng.integers(1, 40))
    model = random_model(n_squares, rng, table_mass=1e3 if seed % 3 == 0 else None,
                         n_tables=seed % 4)
    spread = float(rng.choice([1.0, 3.0, 8.0]))
    points = random_points(n_squares, rng, spread)
    state = State(points, rng.normal(size=points.shape))
    assert check_everything(model, state, rng) > 0 or n_squares == 1


@pytest.mark.parametrize("seed", range(6))
def test_exactly_aligned_states_break_ties_the_same_way(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    n_squares = int(rng.integers(2, 30))
    model = random_model(n_squares, rng, n_tables=0)
    points = grid_points(n_squares, rng)
    state = State(points, np.zeros_like(points))
    assert check_everything(model, state, rng) > 0


def test_no_pairs_and_single_square_cases() -> None:
    rng = np.random.default_rng(0)
    far = random_model(3, rng, n_tables=0)
    points = np.concatenate([square_corners((10.0 * k, 0.0), 1.0, 0.3) for k in range(3)])
    for margin in (0.0, 0.1):
        contacts = new_contacts.find_contacts(far, points, margin)
        assert len(contacts) == 0
        assert_same_contacts(contacts, find_contacts(far, points, margin))
    alone = random_model(1, rng, n_tables=0)
    single = square_corners((0.0, 0.0), 1.0, 0.0)
    assert_same_contacts(new_contacts.find_contacts(alone, single, 1.0),
                         find_contacts(alone, single, 1.0))
    assert deepest_penetration(alone, single) == 0.0


def test_point_rows_with_fixed_points_duplicates_and_no_rows() -> None:
    rng = np.random.default_rng(4)
    n_rows, n_points = 50, 12
    blocks = [(rng.integers(-2, n_points, size=n_rows), rng.normal(size=(n_rows, 2)))
              for _ in range(4)]  # negative: fixed; repeated indices within a row: summed
    assert_same_matrix(new_rows.point_rows(n_rows, n_points, blocks),
                       point_rows(n_rows, n_points, blocks))
    empty = [(np.zeros(0, dtype=np.int64), np.zeros((0, 2)))] * 3
    assert_same_matrix(new_rows.point_rows(0, n_points, empty), point_rows(0, n_points, empty))
    assert_same_matrix(new_rows.point_rows(5, n_points, []), point_rows(5, n_points, []))
    all_fixed = [(np.full(n_rows, -1), rng.normal(size=(n_rows, 2)))]
    assert_same_matrix(new_rows.point_rows(n_rows, n_points, all_fixed),
                       point_rows(n_rows, n_points, all_fixed))


def old_functions(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make the simulation search and the formulations build with the oracles."""
    for searching in (formulations_package, simulation_module):
        monkeypatch.setattr(searching, "find_contacts", find_contacts)
    for module in (velocity_module, seed_module):
        monkeypatch.setattr(module, "point_rows", point_rows)

    def old_side_rows(all_points: FloatArray, contacts: Contacts,
                      model: Model) -> sp.csr_array:
        return point_rows(len(contacts), n_unknown_points(model),
                          side_blocks(all_points, contacts, model))

    def old_rod_rows(model: Model, points: FloatArray) -> tuple[sp.csr_array, FloatArray]:
        blocks, error = rod_blocks(model, points)
        return point_rows(len(error), n_unknown_points(model), blocks), error

    monkeypatch.setattr(velocity_module, "side_rows", old_side_rows)
    monkeypatch.setattr(velocity_module, "rod_rows", old_rod_rows)


@pytest.mark.parametrize("formulation", ["velocity", "seed"])
@pytest.mark.parametrize("name", ["rain-20", "overlap-recovery", "stack-10"])
def test_built_qps_are_bit_identical(formulation: str, name: str,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    model, states = library_states(name)
    scheme = get_formulation(formulation)
    heavy = Model.from_scene(model.scene, table_mass=1e3)
    for which in (model, heavy):
        for state in states:
            new = step_qp(scheme, which, state, 0.01)
            with monkeypatch.context() as patch:
                old_functions(patch)
                old = step_qp(scheme, which, state, 0.01)
            assert_same_contacts(new.contacts, old.contacts)
            assert_same_matrix(new.eq_matrix, old.eq_matrix)
            assert_same_matrix(new.ineq_matrix, old.ineq_matrix)
            for field in ("weights", "target", "eq_rhs", "ineq_rhs"):
                assert np.array_equal(getattr(new, field), getattr(old, field)), field


def test_short_run_matches_a_run_on_the_old_functions(monkeypatch: pytest.MonkeyPatch) -> None:
    new = simulate("rain-8", dt=0.01, steps=130)
    with monkeypatch.context() as patch:
        old_functions(patch)
        old = simulate("rain-8", dt=0.01, steps=130)
    assert np.array_equal(new.points, old.points)
    assert np.array_equal(new.velocities, old.velocities)
    assert new.metrics["n_contacts"].max() > 0
