"""The polish's fill-reducing order of a large pile's unknowns (wuerfel_cvx._sparse)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx import Scene
from wuerfel_cvx._sparse import DISSECTION_MIN_UNKNOWNS, fill_reducing_order, ldl_factor
from wuerfel_cvx.solve import kkt
from wuerfel_cvx.step.simulation import Simulation

pytestmark = pytest.mark.unit


def grid_laplacian(side: int) -> sp.csr_array:
    """The 5-point Laplacian of a ``side`` x ``side`` grid, numbered row by row (SPD)."""
    line = sp.diags_array([-np.ones(side - 1), 2.0 * np.ones(side), -np.ones(side - 1)],
                          offsets=[-1, 0, 1])
    eye = sp.eye_array(side)
    return sp.csr_array(sp.kron(line, eye) + sp.kron(eye, line) + 1e-3 * sp.eye_array(side**2))


def factor_entries(matrix: sp.csr_array, order: np.ndarray) -> int:
    """Entries of ``L`` of ``matrix`` numbered in ``order`` (old index of each position)."""
    permuted = sp.csc_array(matrix[order][:, order])
    upper = sp.csc_array(sp.triu(permuted))
    upper.sort_indices()
    l_ptr, _, _, _, factored = ldl_factor(upper.indptr.astype(np.int64),
                                          upper.indices.astype(np.int64), upper.data)
    assert factored
    return int(l_ptr[-1])


def test_small_graphs_keep_their_order() -> None:
    graph = grid_laplacian(10)
    assert graph.shape[0] < DISSECTION_MIN_UNKNOWNS
    assert np.array_equal(fill_reducing_order(graph), np.arange(100))


def test_nested_dissection_is_a_permutation_that_cuts_the_fill_of_a_grid() -> None:
    """A 60 x 60 grid row by row: a band of 60, about 60 n entries in L; dissected, fewer.

    Measured: 212,459 entries row by row against 74,991 dissected (nested dissection of a
    grid: O(n log n) against O(n^1.5)); asked: at most half.
    """
    graph = grid_laplacian(60)
    order = fill_reducing_order(graph)
    assert np.array_equal(np.sort(order), np.arange(graph.shape[0]))
    natural = factor_entries(graph, np.arange(graph.shape[0]))
    dissected = factor_entries(graph, order)
    assert dissected <= natural / 2, (natural, dissected)


def test_the_polish_solves_a_large_system_alike_in_either_order(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A reduced KKT system of a grid's 3600 unknowns and 1800 rows: the same solution.

    Both orders factor the same regularised matrix and refine against the exact one, so
    their solutions agree to round-off (1e-12 relative asked; measured 2.2e-16, the residual
    4.4e-15).
    """
    rng = np.random.default_rng(0)
    hessian = grid_laplacian(60)
    n = hessian.shape[0]
    rows = sp.random_array((n // 2, n), density=4.0 / n, random_state=rng) + sp.hstack(
        [sp.eye_array(n // 2), sp.csr_array((n // 2, n - n // 2))])
    block = sp.coo_array(sp.block_array([[hessian, rows.T], [rows, None]]))
    size = block.shape[0]
    diagonal = np.arange(n, size)  # the rows' zero diagonal, stored as the polish needs
    matrix = sp.csc_matrix((np.concatenate([block.data, np.zeros(size - n)]),
                            (np.concatenate([block.row, diagonal]),
                             np.concatenate([block.col, diagonal]))), shape=(size, size))
    matrix.sort_indices()
    rhs = rng.standard_normal(matrix.shape[0])
    dissected = kkt.solve_reduced(matrix, n, rhs)
    monkeypatch.setattr(kkt, "DISSECTION_MIN_UNKNOWNS", 10**9)  # small: as it comes
    natural = kkt.solve_reduced(matrix, n, rhs)
    assert dissected is not None and natural is not None
    assert np.max(np.abs(matrix @ dissected - rhs)) <= 1e-10 * np.max(np.abs(rhs))
    assert np.max(np.abs(dissected - natural)) <= 1e-12 * np.max(np.abs(natural))


@pytest.mark.integration
def test_a_large_resting_pile_refines_on_its_last_factor(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """field-pyramid-30 (1395 unknowns) at rest with reuse: factored on its first steps only.

    The reused steps' systems have the pattern and nearly the numbers of the last one: they
    are solved by refinement on its factor, as exact as the reuse asks (every step verified,
    reused, residuals at most 1e-10).
    """
    factorizations = []
    original = kkt.equilibrated_solution

    def counted(*args: object, **kwargs: object) -> object:
        factorizations.append(1)
        return original(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(kkt, "equilibrated_solution", counted)
    scene = Scene.named("field-pyramid-30")
    simulation = Simulation(scene, dt=0.01, solver="PIQP", reuse_active_sets=True)
    for _ in range(2):
        simulation.step()
    first = len(factorizations)
    for _ in range(4):
        simulation.step()
    metrics = simulation.trajectory().metrics
    assert (metrics["polish"].iloc[1:] == kkt.REUSED).all()
    assert metrics["verified"].all()
    assert len(factorizations) == first  # no new factorization on the last four steps


def test_the_order_sees_the_entries_the_factor_fills_on() -> None:
    """A sticking contact of the friction problem: ``S x + s >= 0`` and ``-S x + s >= 0``.

    Both rows tight: their products with the slack ``s`` cancel in ``A' A``, and ``S``
    stores a zero (an axis-aligned edge's slip has no ``y`` part).  The factorization fills
    on the stored pattern, so the order's graph must hold those entries too.
    """
    x, y, s = 0, 1, 2
    slip = sp.csr_array((np.array([1.0, 0.0, 1.0, -1.0, 0.0, 1.0]),
                         np.array([x, y, s, x, y, s]), np.array([0, 3, 6])), shape=(2, 3))
    hessian = sp.diags_array([2.0, 2.0, 0.0])
    matrix = sp.csc_array(sp.block_array([[hessian, slip.T], [slip, None]]))
    assert np.count_nonzero(matrix.data == 0.0) >= 4  # S's zeros, stored (both ways)
    coupling = matrix[3:, :3]
    by_numbers = sp.csr_array(coupling.T @ coupling)
    assert by_numbers[x, s] == 0.0 and by_numbers[y, s] == 0.0  # what was ordered before
    graph = kkt._elimination_graph(matrix, 3)
    edges = {(int(i), int(j)) for i, j in zip(*graph.nonzero(), strict=True)}
    assert {(x, s), (s, x), (y, s), (x, y)} <= edges
