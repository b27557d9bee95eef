"""The compiled kernels give their NumPy references' results bit for bit, stage by stage.

The product runs the compiled kernels only (each in its stage's module: ``step/contacts.py``,
``formulations/rows.py``, ``formulations/motion.py``, ``formulations/velocity.py``,
``step/criteria.py``, ``solve/residual_kernel.py``); the
batched NumPy code they replaced is kept in ``tests/reference_kernels.py``.  One test per stage
compares the two on the same inputs: the states of ``tests/test_contacts_fast.py``
(library scenes, random overlapping squares of random size and angle against random
tables, exactly aligned grids with corner-on-corner ties), random boxes of every size and
angle, and the step QPs of short runs.  The golden digests (``tests/test_determinism.py``)
pin whole runs.  The warm starts' row ids are compared in ``tests/test_warm_start.py``;
the dense rows against scipy in ``tests/test_dense_forms.py``.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import scipy.sparse as sp

import reference_kernels as reference
from test_contacts_fast import (
    LIBRARY,
    grid_points,
    library_states,
    margins,
    random_model,
    random_points,
)
from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.formulations.motion import rigid_step
from wuerfel_cvx.formulations.qp import StepQP
from wuerfel_cvx.formulations.rigid import RigidFormulation, rigid_objective
from wuerfel_cvx.formulations.rows import (
    body_rows,
    held_table_blocks,
    n_unknown_points,
    point_rows,
    rod_rows,
    seed_side_blocks,
    side_rows,
)
from wuerfel_cvx.formulations.velocity import (
    VelocityFormulation,
    closest_approach,
    rows_along,
)
from wuerfel_cvx.formulations.velocity import (
    _reaches as velocity_reaches,
)
from wuerfel_cvx.scenes.geometry import FloatArray, rectangle_corners
from wuerfel_cvx.solve import residual_kernel
from wuerfel_cvx.solve.paths import (
    VERIFY_FACTOR,
    Residuals,
    StepSolution,
    _checked_scales,
    kkt_residuals,
)
from wuerfel_cvx.solve.scaling import data_magnitude
from wuerfel_cvx.step import contacts
from wuerfel_cvx.step.contacts import find_contacts
from wuerfel_cvx.step.criteria import (
    contact_criteria,
    gaps_after,
    normal_impulses,
    push_bound,
    row_pushes,
)
from wuerfel_cvx.step.model import Model, State
from wuerfel_cvx.step.simulation import _finite as simulation_finite

pytestmark = pytest.mark.integration

DT = 0.01


def assert_same_bits(compiled: np.ndarray, expected: np.ndarray) -> None:
    compiled, expected = np.asarray(compiled), np.asarray(expected)
    assert compiled.shape == expected.shape and compiled.dtype == expected.dtype
    assert compiled.tobytes() == expected.tobytes()  # signed zeros included


def assert_same_matrix(compiled: sp.csr_array, expected: sp.csr_array) -> None:
    """The same canonical CSR matrix: shape, index arrays and their dtypes, values."""
    assert compiled.shape == expected.shape
    assert compiled.has_canonical_format and expected.has_canonical_format
    for name in ("indptr", "indices", "data"):
        assert_same_bits(getattr(compiled, name), getattr(expected, name))


# --------------------------------------------------------------------------------------
# Contact search
# --------------------------------------------------------------------------------------


def contact_states(kind: str, key: str | int
                   ) -> tuple[Model, tuple[State, ...], np.random.Generator]:
    if kind == "library":
        model, states = library_states(str(key))
        return model, states, np.random.default_rng(5)
    seed = int(key)
    if kind == "random":  # overlapping squares of random size and angle, random tables
        rng = np.random.default_rng(1000 + seed)
        n_squares = int(rng.integers(2, 60))
        model = random_model(n_squares, rng, n_tables=seed % 4)
        points = random_points(n_squares, rng, float(rng.choice([1.0, 3.0, 8.0])))
        return model, (State(points, rng.normal(size=points.shape)),), rng
    rng = np.random.default_rng(2000 + seed)  # exactly aligned
    n_squares = int(rng.integers(2, 30))
    model = random_model(n_squares, rng, n_tables=0)
    points = grid_points(n_squares, rng)
    return model, (State(points, np.zeros_like(points)),), rng


def same_contact_search(model: Model, state: State, rng: np.random.Generator) -> int:
    """Both phases on ``state`` for every margin of ``margins``; the contacts found."""
    found = 0
    all_points = model.all_points(state.points)
    corners = all_points.reshape(-1, 4, 2)
    for margin in margins(model, state, rng):
        reach = np.broadcast_to(np.asarray(margin, dtype=np.float64), (model.n_bodies,))
        pairs = contacts.body_pairs(model, all_points, reach)
        assert_same_bits(pairs, reference.body_pairs(model, all_points, reach))
        searched, expected_contacts = (find_contacts(model, state.points, margin),
                                       reference.find_contacts(model, state.points, reach))
        for field in dataclasses.fields(searched):
            assert_same_bits(getattr(searched, field.name),
                             getattr(expected_contacts, field.name))
        same_float(searched.deepest_penetration(),
                   reference.deepest_penetration(expected_contacts))
        if len(pairs) == 0:
            continue
        expected = reference.narrow_phase(corners, pairs[:, 0], pairs[:, 1], reach)
        compiled = contacts.narrow_phase(corners, pairs[:, 0], pairs[:, 1], reach)
        for ours, theirs in zip(compiled, expected, strict=True):
            assert_same_bits(ours, theirs)  # same rows, same order, same bits
        found += len(expected[0])
    return found


CONTACT_CASES = ([("library", name) for name in sorted(LIBRARY)]
                 + [("random", seed) for seed in range(40)]
                 + [("aligned", seed) for seed in range(12)])


@pytest.mark.parametrize(("kind", "key"), CONTACT_CASES)
def test_the_contact_search_is_the_references(kind: str, key: str | int) -> None:
    model, states, rng = contact_states(kind, key)
    assert sum(same_contact_search(model, state, rng) for state in states) > 0


def test_the_all_pairs_loop_lists_the_sorted_trees_pairs() -> None:
    """Up to ``ALL_PAIRS_LIMIT`` centres the compiled loop lists the tree's pairs, sorted.

    Random clouds at many scales and radii (from none to all pairs within reach), on both
    sides of the limit, and integer grids whose distances tie the radius exactly (the tree
    counts ``d == r`` in).
    """
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(7)
    limit = contacts.ALL_PAIRS_LIMIT
    clouds = [rng.normal(size=(int(rng.integers(2, limit + 20)), 2)) * rng.uniform(0.01, 10.0)
              for _ in range(300)]
    grid = np.array([[x, y] for x in range(8) for y in range(8)], dtype=np.float64)
    clouds += [grid, grid[:5], grid * 0.5]
    for centers in clouds:
        for radius in (0.0, 0.5, 1.0, 2.0, float(rng.uniform(0.0, 8.0)), 1e3):
            tree = cKDTree(centers).query_pairs(r=radius, output_type="set")
            expected = contacts.tree_pairs(centers, radius)
            assert {tuple(pair) for pair in expected.tolist()} == tree  # the tree's pairs
            assert np.array_equal(expected, np.array(sorted(tree), dtype=np.int64
                                                     ).reshape(-1, 2))  # sorted
            assert_same_bits(contacts.candidate_pairs(centers, radius), expected)


# --------------------------------------------------------------------------------------
# Rows
# --------------------------------------------------------------------------------------


def same_rows(model: Model, state: State) -> int:
    """Every block kind's rows, the rod and side rows and the rigid body rows; the contacts."""
    contacts_found = find_contacts(model, state.points,
                                   VelocityFormulation().body_reach(model, state, DT))
    all_points = model.all_points(state.points)
    n_unknown = n_unknown_points(model)
    block_sets = [reference.side_blocks(all_points, contacts_found, model),
                  seed_side_blocks(all_points, contacts_found, model),
                  reference.rod_blocks(model, state.points)[0], held_table_blocks(model)]
    for blocks in block_sets:
        rows = len(blocks[0][0]) if blocks else 0
        assert_same_matrix(point_rows(rows, n_unknown, blocks),
                           reference.point_rows(rows, n_unknown, blocks))
    assert_same_matrix(side_rows(all_points, contacts_found, model),
                       reference.side_rows(all_points, contacts_found, model))
    (rods, error), (expected_rods, expected_error) = (
        rod_rows(model, state.points), reference.rod_rows(model, state.points))
    assert_same_matrix(rods, expected_rods)
    assert_same_bits(error, expected_error)
    if model.table_mass is None:
        corner_rows = point_rows(len(contacts_found), n_unknown, block_sets[0])
        assert_same_matrix(body_rows(corner_rows, state.points),
                           reference.body_rows(corner_rows, state.points))
    return len(contacts_found)


def row_states(kind: str, key: str | int) -> list[tuple[Model, State]]:
    if kind == "library":
        model, states = library_states(str(key))
        heavy = Model.from_scene(model.scene, table_mass=1e3)  # tables become unknowns
        return [(which, state) for state in states for which in (model, heavy)]
    seed = int(key)
    rng = np.random.default_rng(3000 + seed)
    n_squares = int(rng.integers(2, 50))
    model = random_model(n_squares, rng, table_mass=1e3 if seed % 4 == 0 else None,
                         n_tables=seed % 3)
    points = random_points(n_squares, rng, float(rng.choice([1.0, 3.0])))
    return [(model, State(points, rng.normal(size=points.shape)))]


def same_duplicate_rows() -> int:
    """Rows holding a point twice: summed by scipy, as the reference sums them."""
    rng = np.random.default_rng(7)
    index = rng.integers(-1, 4, size=(30, 3))
    index[:5, 1] = index[:5, 0] = 2
    blocks = [(index[:, b], rng.normal(size=(30, 2))) for b in range(3)]
    compiled = point_rows(30, 4, blocks)
    assert isinstance(compiled, sp.csr_array)
    assert_same_matrix(compiled, reference.point_rows(30, 4, blocks))
    return 30


ROW_CASES = ([("library", name) for name in sorted(LIBRARY)]
             + [("random", seed) for seed in range(16)] + [("duplicates", 0)])


@pytest.mark.parametrize(("kind", "key"), ROW_CASES)
def test_the_rows_are_the_references(kind: str, key: str | int) -> None:
    if kind == "duplicates":
        assert same_duplicate_rows() > 0
        return
    assert sum(same_rows(model, state) for model, state in row_states(kind, key)) > 0


# --------------------------------------------------------------------------------------
# Rigid motion
# --------------------------------------------------------------------------------------


def same_update(corners: FloatArray, state: State, solution: FloatArray) -> None:
    """The rigid step from corner velocities, and the corner velocities of body velocities."""
    stepped = rigid_step(corners, state.points, state.velocities, DT)
    expected = reference.rigid_step(corners, state.points, state.velocities, DT)
    assert_same_bits(stepped.points, expected.points)
    assert_same_bits(stepped.velocities, expected.velocities)
    assert_same_bits(RigidFormulation().new_velocities(state, solution, DT),
                     reference.corner_velocities(state, solution))


def same_objective(model: Model, state: State) -> None:
    """The rigid formulation's weights and target, and the contact reach."""
    for ours, theirs in zip(rigid_objective(model, state, DT),
                            reference.rigid_objective(model, state, DT), strict=True):
        assert_same_bits(ours, theirs)
    velocity = VelocityFormulation()
    assert_same_bits(velocity.body_reach(model, state, DT),
                     reference.body_reach(model, state, DT, velocity.contact_margin))


def same_library_motion(name: str) -> None:
    """Resting stacks (zero and negative-zero velocities) and random velocities."""
    model, states = library_states(name)
    rng = np.random.default_rng(11)
    for state in states:
        same_objective(model, state)
        same_objective(model, State(state.points,
                                    rng.normal(scale=5.0, size=state.velocities.shape)))
        same_update(model.reference_corners, state, rng.normal(size=3 * model.n_boxes))
        resting = State(state.points, -np.zeros_like(state.velocities))  # negative zeros
        same_update(model.reference_corners, resting, np.zeros(3 * model.n_boxes))


def same_random_motion(seed: int) -> None:
    """Boxes of every size and angle, not exactly rigid, some corners at rest."""
    rng = np.random.default_rng(5000 + seed)
    count = int(rng.integers(1, 60))
    sizes = rng.uniform(0.01, 5.0, size=(count, 2)) * 10.0 ** rng.integers(-2, 3, size=(count, 1))
    corners = np.stack([rectangle_corners((0.0, 0.0), w, h, 0.0) for w, h in sizes])
    angles = rng.uniform(-4.0, 4.0, size=count)
    centres = rng.uniform(-50.0, 50.0, size=(count, 2))
    points = np.concatenate([rectangle_corners(c, w, h, a)
                             for c, (w, h), a in zip(centres, sizes, angles, strict=True)])
    points += rng.normal(scale=1e-9, size=points.shape)  # not exactly rigid
    velocities = rng.normal(scale=float(rng.choice([1e-3, 1.0, 30.0])), size=points.shape)
    velocities[rng.random(points.shape) < 0.2] = 0.0
    same_update(corners, State(points, velocities), rng.normal(size=3 * count))


MOTION_CASES = ([("library", name) for name in sorted(LIBRARY)]
                + [("random", seed) for seed in range(12)])


@pytest.mark.parametrize(("kind", "key"), MOTION_CASES)
def test_the_rigid_motion_is_the_references(kind: str, key: str | int) -> None:
    if kind == "library":
        same_library_motion(str(key))
    else:
        same_random_motion(int(key))


# --------------------------------------------------------------------------------------
# Closest approach
# --------------------------------------------------------------------------------------


def same_approach(model: Model, state: State, about: FloatArray) -> tuple[int, int]:
    """The body motion, the closest approaches and their rows along ``about``'s motion.

    Where the compiled rows are one per contact, the reference's two rows of each contact
    must be one row (the closest-approach row's right-hand side at most the rate row's).
    Returns the contacts compared and how many of them start past their face's end.
    """
    formulation = VelocityFormulation()
    found = find_contacts(model, state.points, formulation.body_reach(model, state, DT))
    ours = closest_approach(model, state.points, found, about, DT, formulation.push_speed)
    motion, closest, margin, rate, closest_rate, violation = reference.closest_approach(
        model, state.points, found, about, DT, formulation.push_speed)
    for field in dataclasses.fields(motion):
        assert_same_bits(getattr(ours.motion, field.name), getattr(motion, field.name))
    pose = closest_approach(model, state.points, found, 2.0 - about, DT,  # another motion
                            formulation.push_speed).motion
    posed = closest_approach(model, state.points, found, about, DT, formulation.push_speed,
                             pose)  # a later pass's: the first pass's fitted bodies
    for field in dataclasses.fields(posed):
        if field.name != "motion":
            assert_same_bits(getattr(posed, field.name), getattr(ours, field.name))
    for field in dataclasses.fields(motion):
        assert_same_bits(getattr(posed.motion, field.name), getattr(motion, field.name))
    if len(found) == 0:
        return 0, 0
    for compiled, expected in ((ours.closest, closest), (ours.margin, margin),
                               (ours.rate, rate), (ours.closest_rate, closest_rate),
                               (ours.violation, violation)):
        assert_same_bits(compiled, expected)
    rows = rows_along(model, found, ours)
    matrix, rhs = reference.rows_along(model, found, motion, about, closest, margin, rate,
                                       closest_rate)
    m = len(found)
    if rows.matrix.shape[0] == m:  # one row per contact: each contact's two rows are one
        rate_rows = matrix[:m]
        assert (rate_rows != matrix[m:]).nnz == 0 and np.all(rhs[m:] <= rhs[:m])
        matrix, rhs = rate_rows, rhs[:m]
    assert_same_matrix(rows.matrix, matrix)
    assert_same_bits(rows.rhs, rhs)
    past = 0 if found.clearance is None else int(np.sum(found.clearance > 0.0))
    return len(found), past


def approach_estimates(model: Model, state: State,
                       rng: np.random.Generator) -> list[FloatArray]:
    """Velocity estimates: the unconstrained ``v + dt g``, random ones, fast spins, rest."""
    n_unknown = n_unknown_points(model)
    free = np.zeros((n_unknown, 2))
    free[: model.n_points] = state.velocities + DT * model.gravity
    spins = np.zeros((n_unknown, 2))
    turned = state.points.reshape(-1, 4, 2) - state.points.reshape(-1, 4, 2).mean(axis=1)[
        :, None, :]
    spins[: model.n_points] = (rng.uniform(-30.0, 30.0, size=(model.n_boxes, 1, 1))
                               * turned[..., ::-1] * np.array([-1.0, 1.0])).reshape(-1, 2)
    return [free.ravel(), rng.normal(scale=3.0, size=2 * n_unknown), spins.ravel(),
            -np.zeros(2 * n_unknown)]


@pytest.mark.parametrize(("kind", "key"), MOTION_CASES)
def test_the_reach_of_a_pass_is_the_references(kind: str, key: str | int) -> None:
    """The reach searched and a solution's travel, at the estimates of the approach tests."""
    rng = np.random.default_rng(37)
    formulation = VelocityFormulation()
    for model, state in row_states(kind, key):
        for about in approach_estimates(model, state, rng):
            ours = velocity_reaches(state.velocities, about.reshape(-1, 2)[: model.n_points],
                                    model.n_tables, 0.5 * formulation.contact_margin, DT,
                                    DT * model.gravity_norm, DT * DT * model.gravity_norm)
            theirs = reference.reaches(model, state, about, DT, formulation.contact_margin)
            assert_same_bits(ours[0], theirs[0])
            assert_same_bits(ours[1], theirs[1])
            assert ours[2] == theirs[2]


APPROACH_CASES = ([("library", name) for name in sorted(LIBRARY)]
                  + [("random", seed) for seed in range(16)])


@pytest.mark.parametrize(("kind", "key"), APPROACH_CASES)
def test_the_closest_approach_is_the_references(kind: str, key: str | int) -> None:
    rng = np.random.default_rng(17)
    compared = [same_approach(model, state, about)
                for model, state in row_states(kind, key)
                for about in approach_estimates(model, state, rng)]
    assert sum(count for count, _ in compared) > 0


def test_the_closest_approach_of_points_past_a_face_is_the_references() -> None:
    """The card house starts with corners past their faces' ends (``test_face_gap.py``)."""
    scene = Scene.named("card-house")
    model, state = Model.from_scene(scene), State.initial(scene)
    rng = np.random.default_rng(19)
    assert sum(same_approach(model, state, about)[1]
               for about in approach_estimates(model, state, rng)) > 0


# --------------------------------------------------------------------------------------
# KKT check
# --------------------------------------------------------------------------------------


def step_qps(scene: str, formulation: str, steps: int) -> list[tuple[StepQP, StepSolution]]:
    """The QPs and solutions of a short run."""
    seen: list[tuple[StepQP, StepSolution]] = []
    simulate(scene, dt=DT, steps=steps, solver="OSQP", formulation=formulation,
             observer=lambda step, qp, solution: seen.append((qp, solution)))
    return seen


def assert_same_residuals(qp: StepQP, x: FloatArray, y: FloatArray, z: FloatArray) -> None:
    compiled: Residuals = kkt_residuals(qp, x, y, z)
    expected: Residuals = kkt_residuals(reference.general_route(qp), x, y, z)
    for name in ("primal", "dual", "complementarity"):
        ours, theirs = getattr(compiled, name), getattr(expected, name)
        assert (ours == theirs and np.signbit(ours) == np.signbit(theirs)) or (
            np.isnan(ours) and np.isnan(theirs)), name


def same_data_check(qp: StepQP, rng: np.random.Generator) -> None:
    """The data check's scales (ordinary and scaled data) and its failures."""
    for target, weights in ((qp.target, qp.weights), (qp.target * 3e4, qp.weights * 1e-3)):
        varied = dataclasses.replace(qp, target=target, weights=weights)
        assert _checked_scales(varied, 0, "OSQP") == _checked_scales(
            reference.general_route(varied), 0, "OSQP")
    finite, magnitude, largest = residual_kernel.data_summary(
        qp.weights, qp.target, qp.eq_matrix.data, qp.eq_rhs, qp.ineq_matrix.data, qp.ineq_rhs)
    assert finite and magnitude == data_magnitude(qp) and largest == qp.weights.max()
    field = str(rng.choice(["weights", "target", "eq_rhs", "ineq_rhs"]))
    values = np.array(getattr(qp, field), dtype=np.float64)
    if values.size:
        values[rng.integers(values.size)] = rng.choice([np.nan, np.inf, -np.inf])
        broken = dataclasses.replace(qp, **{field: values})
        for route in (broken, reference.general_route(broken)):
            with pytest.raises(StepFailure, match=f"non-finite {field}"):
                _checked_scales(route, 0, "OSQP")


KKT_CASES = [("stack-5", "velocity", 30), ("stack-5", "rigid", 30),
             ("rain-10", "velocity-baumgarte", 30), ("two-corner-landing", "seed", 30),
             ("pyramid-4", "rigid", 30),
             ("spinning-flight", "rigid", 1)]  # the last: a QP without rows


@pytest.mark.parametrize(("scene", "formulation", "steps"), KKT_CASES)
def test_the_kkt_check_is_the_references(scene: str, formulation: str, steps: int) -> None:
    """At the solvers' answers, perturbed, with NaN multipliers (no duals returned)."""
    rng = np.random.default_rng(4)
    checked = 0
    for qp, solution in step_qps(scene, formulation, steps):
        if qp.cost_factor is not None or qp.ineq_upper is not None:
            continue  # the general NumPy check is the product's own for these
        y = rng.normal(size=qp.n_equalities)  # the solution does not carry y: any will do
        z = solution.ineq_dual
        assert_same_residuals(qp, solution.x, y, z)
        assert_same_residuals(qp, solution.x + rng.normal(scale=1e-3, size=solution.x.shape),
                              y, z + rng.normal(size=z.shape))
        if z.size:
            assert_same_residuals(qp, solution.x, y, np.full(z.shape, np.nan))
        same_data_check(qp, rng)
        checked += 1
    assert checked > 0


# --------------------------------------------------------------------------------------
# The physical check
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(("kind", "key"), ROW_CASES[:-1])
def test_the_gaps_after_a_step_are_the_references(kind: str, key: str | int) -> None:
    rng = np.random.default_rng(23)
    compared = 0
    for model, state in row_states(kind, key):
        found = find_contacts(model, state.points, 0.1)
        moved = state.points + 0.01 * rng.normal(size=state.points.shape)  # after a step
        all_points = model.all_points(moved)
        assert_same_bits(gaps_after(all_points, found),
                         reference.gaps_after(all_points, found))
        compared += len(found)
    assert compared > 0


def same_float(ours: float, theirs: float) -> None:
    """The same number, the sign of a zero included; NaN for NaN."""
    assert (np.isnan(ours) and np.isnan(theirs)) or (
        ours == theirs and np.signbit(ours) == np.signbit(theirs))


def edge_values(rng: np.random.Generator, size: int, nan: bool) -> FloatArray:
    """Random values with zeros of both signs, negatives and (if ``nan``) a NaN."""
    values = rng.choice([0.0, -0.0, 1.5, -2.0], size=size) * rng.uniform(0.5, 1.0, size=size)
    if nan and size:
        values[rng.integers(size)] = np.nan
    return values


@pytest.mark.parametrize(("scene", "formulation", "steps"), KKT_CASES)
def test_the_row_pushes_are_the_references(scene: str, formulation: str, steps: int) -> None:
    """At the solvers' answers, and at multipliers of every sign, zeros and NaN included."""
    rng = np.random.default_rng(29)
    units = VelocityFormulation().row_units(DT)
    checked = 0
    for qp, solution in step_qps(scene, formulation, steps):
        count = len(qp.contacts)
        for z in (solution.ineq_dual, edge_values(rng, qp.n_inequalities, nan=False),
                  edge_values(rng, qp.n_inequalities, nan=True)):
            if qp.n_inequalities:
                varied = dataclasses.replace(solution, ineq_dual=z)
                ours = row_pushes(qp, varied, units)
                theirs = reference.row_pushes(qp, solution.x, z, units.impulse_per_multiplier,
                                              units.gap_per_slack)
                for column in ours:
                    same_float(ours[column], theirs[column])
            assert_same_bits(normal_impulses(qp, dataclasses.replace(solution, ineq_dual=z),
                                             units),
                             reference.normal_impulses(count, z, units.impulse_per_multiplier))
        checked += 1
    assert checked > 0


@pytest.mark.parametrize(("kind", "key"), ROW_CASES[:-1])
def test_the_signorini_column_and_the_push_bounds_speed_are_the_references(
        kind: str, key: str | int) -> None:
    rng = np.random.default_rng(31)
    compared = 0
    for model, state in row_states(kind, key):
        found = find_contacts(model, state.points, 0.1)
        moved = state.points + 0.01 * rng.normal(size=state.points.shape)
        for normal in (edge_values(rng, len(found), nan=False),
                       edge_values(rng, len(found), nan=True)):
            if len(found):
                ours = contact_criteria(None, normal, model, moved, found)
                same_float(ours["signorini_violation_Nsm"],
                           reference.signorini(model.all_points(moved), found, normal))
        for velocities in (state.velocities, np.zeros_like(state.velocities),
                           edge_values(rng, state.velocities.size, nan=True).reshape(-1, 2)):
            expected = (VERIFY_FACTOR * 1e-6 * DT * (0.5 + model.total_mass * (
                speed := model.gravity_norm * DT + reference.fastest_speed(velocities))
                * (1.0 + speed)))
            same_float(push_bound(model, State(state.points, velocities), DT, 1e-6), expected)
        compared += len(found)
    assert compared > 0


def test_the_deepest_penetration_and_the_finite_check_are_the_references() -> None:
    """Distances and states with zeros of both signs, NaN and infinities."""
    rng = np.random.default_rng(41)
    for size in (0, 1, 3, 9):
        for nan in (False, True):
            distance = edge_values(rng, size, nan)
            index = np.zeros(size, dtype=np.int64)
            found = contacts.Contacts(index, index, index, index, index, distance)
            same_float(found.deepest_penetration(), reference.deepest_penetration(found))
            points = edge_values(rng, 2 * size, nan).reshape(-1, 2)
            for velocities in (np.zeros_like(points), np.full_like(points, np.inf)):
                state = State(points, velocities)
                assert simulation_finite(state.points, state.velocities) == reference.finite(
                    state)
