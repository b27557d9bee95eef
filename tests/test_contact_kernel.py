"""The compiled contact search (numba) equals the NumPy search bit for bit.

The NumPy paths (:func:`wuerfel_cvx.contacts.body_pairs` and
:func:`wuerfel_cvx.contacts.narrow_phase`) are the reference; the compiled ones
(:mod:`wuerfel_cvx.contact_kernel`) claim the same pairs and the same contacts in the same
order with bit-identical distances, for finite corners.  Both are run here on the
states of ``tests/test_contacts_fast.py`` (library scenes, random overlapping squares of
random size and angle against random tables, exactly aligned grids with corner-on-corner
ties) and with every margin that test uses.
"""

from __future__ import annotations

import numpy as np
import pytest

from test_contacts_fast import (
    LIBRARY,
    grid_points,
    library_states,
    margins,
    random_model,
    random_points,
)
from wuerfel_cvx import _numba, contact_kernel, contacts, simulate
from wuerfel_cvx.model import Model, State

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(not contact_kernel.AVAILABLE, reason="numba is not installed")]


def assert_same_narrow_phase(model: Model, state: State, rng: np.random.Generator,
                             monkeypatch: pytest.MonkeyPatch) -> int:
    """Both broad and narrow phases on ``state`` for every margin; the contacts found."""
    found = 0
    all_points = model.all_points(state.points)
    corners = all_points.reshape(-1, 4, 2)
    for margin in margins(model, state, rng):
        reach = np.broadcast_to(np.asarray(margin, dtype=np.float64), (model.n_bodies,))
        broad = []
        for enabled in (False, True):
            monkeypatch.setattr(_numba, "enabled", enabled)
            broad.append(contacts.body_pairs(model, all_points, reach))
        assert broad[1].dtype == broad[0].dtype
        assert np.array_equal(broad[1], broad[0])  # the same pairs in the same order
        pairs = broad[0]
        if len(pairs) == 0:
            continue
        reference = contacts.narrow_phase(corners, pairs[:, 0], pairs[:, 1], reach)
        compiled = contact_kernel.narrow_phase(corners, pairs[:, 0], pairs[:, 1], reach)
        for ours, theirs in zip(compiled, reference, strict=True):
            assert ours.dtype == np.asarray(theirs).dtype
            assert np.array_equal(ours, theirs)  # same rows, same order, same bits
        found += len(reference[0])
    return found


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_library_states_give_the_same_contacts(monkeypatch: pytest.MonkeyPatch,
                                                name: str) -> None:
    model, states = library_states(name)
    rng = np.random.default_rng(5)
    assert sum(assert_same_narrow_phase(model, state, rng, monkeypatch)
               for state in states) > 0


@pytest.mark.parametrize("seed", range(40))
def test_random_overlapping_states_give_the_same_contacts(monkeypatch: pytest.MonkeyPatch,
                                                          seed: int) -> None:
    rng = np.random.default_rng(1000 + seed)
    n_squares = int(rng.integers(2, 60))
    model = random_model(n_squares, rng, n_tables=seed % 4)
    points = random_points(n_squares, rng, float(rng.choice([1.0, 3.0, 8.0])))
    state = State(points, rng.normal(size=points.shape))
    assert assert_same_narrow_phase(model, state, rng, monkeypatch) > 0


@pytest.mark.parametrize("seed", range(12))
def test_exactly_aligned_states_give_the_same_contacts(monkeypatch: pytest.MonkeyPatch,
                                                       seed: int) -> None:
    rng = np.random.default_rng(2000 + seed)
    n_squares = int(rng.integers(2, 30))
    model = random_model(n_squares, rng, n_tables=0)
    points = grid_points(n_squares, rng)
    state = State(points, np.zeros_like(points))
    assert assert_same_narrow_phase(model, state, rng, monkeypatch) > 0


@pytest.mark.parametrize(("scene", "steps"), [("stack-5", 20), ("rain-10", 120)])
def test_a_run_is_bit_identical_on_either_narrow_phase(monkeypatch: pytest.MonkeyPatch,
                                                        scene: str, steps: int) -> None:
    runs = []
    for use_kernel in (False, True):
        monkeypatch.setattr(_numba, "enabled", use_kernel)
        runs.append(simulate(scene, dt=0.01, steps=steps, solver="OSQP"))
    assert np.array_equal(runs[0].points, runs[1].points)
    assert np.array_equal(runs[0].velocities, runs[1].velocities)
    assert runs[0].metrics["n_contacts"].sum() > 0


def test_the_all_pairs_loop_lists_the_sorted_trees_pairs() -> None:
    """Up to ``ALL_PAIRS_LIMIT`` centres the compiled loop lists the tree's pairs, sorted.

    Random clouds at many scales and radii (from none to all pairs within reach), on both
    sides of the limit, and integer grids whose distances tie the radius exactly (the tree
    counts ``d == r`` in).
    """
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(7)
    limit = contact_kernel.ALL_PAIRS_LIMIT
    clouds = [rng.normal(size=(int(rng.integers(2, limit + 20)), 2)) * rng.uniform(0.01, 10.0)
              for _ in range(300)]
    grid = np.array([[x, y] for x in range(8) for y in range(8)], dtype=np.float64)
    clouds += [grid, grid[:5], grid * 0.5]
    for centers in clouds:
        for radius in (0.0, 0.5, 1.0, 2.0, float(rng.uniform(0.0, 8.0)), 1e3):
            tree = cKDTree(centers).query_pairs(r=radius, output_type="set")
            expected = contact_kernel.tree_pairs(centers, radius)
            assert {tuple(pair) for pair in expected.tolist()} == tree  # the tree's pairs
            assert np.array_equal(expected, np.array(sorted(tree), dtype=np.int64
                                                     ).reshape(-1, 2))  # sorted
            found = contact_kernel.candidate_pairs(centers, radius)
            assert found.dtype == expected.dtype
            assert np.array_equal(found, expected)
