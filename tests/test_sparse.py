"""A CSR array made without scipy's checks is the one scipy's constructor makes."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from wuerfel_cvx import _sparse
from wuerfel_cvx._sparse import canonical_csr, empty_rows

pytestmark = pytest.mark.unit


def _constructed(data: np.ndarray, indices: np.ndarray, indptr: np.ndarray,
                 shape: tuple[int, int]) -> sp.csr_array:
    matrix = sp.csr_array((data, indices, indptr), shape=shape)
    matrix.has_canonical_format = True
    return matrix


def _assert_same(ours: sp.csr_array | sp.csc_matrix, theirs: sp.csr_array | sp.csc_matrix
                 ) -> None:
    assert type(ours) is type(theirs)
    assert ours.shape == theirs.shape and ours.nnz == theirs.nnz
    assert sorted(vars(ours)) == sorted(vars(theirs))
    for name in ("data", "indices", "indptr"):
        mine, reference = getattr(ours, name), getattr(theirs, name)
        assert mine.dtype == reference.dtype
        assert np.array_equal(mine, reference)
    assert ours.has_canonical_format and ours.has_sorted_indices


@pytest.mark.parametrize("index_dtype", [np.int32, np.int64])
def test_canonical_rows_give_the_constructors_matrix(index_dtype: type) -> None:
    data = np.array([1.5, -2.0, 3.25, 4.0, -0.5])
    indices = np.array([0, 3, 1, 2, 4], dtype=index_dtype)
    indptr = np.array([0, 2, 2, 5], dtype=index_dtype)
    ours = canonical_csr(data, indices, indptr, (3, 6))
    theirs = _constructed(data, indices, indptr, (3, 6))
    _assert_same(ours, theirs)
    vector = np.arange(6.0)
    assert np.array_equal(ours @ vector, theirs @ vector)
    assert np.array_equal(ours.T.toarray(), theirs.T.toarray())
    assert np.array_equal(sp.vstack([ours, ours]).toarray(), sp.vstack([theirs, theirs]).toarray())


def test_no_rows_are_the_constructors_empty_matrix() -> None:
    theirs = sp.csr_array((0, 7))
    assert theirs.has_canonical_format  # as the step QP's declaration asks it
    _assert_same(empty_rows(7), theirs)


def test_an_unknown_scipy_layout_goes_through_the_constructor(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_sparse, "_TEMPLATE", None)
    data, indices, indptr = np.array([2.0]), np.array([1]), np.array([0, 0, 1])
    _assert_same(canonical_csr(data, indices, indptr, (2, 2)),
                 _constructed(data, indices, indptr, (2, 2)))


def _constructed_csc(rows: sp.csr_array) -> sp.csc_matrix:
    matrix = sp.csc_matrix(rows)
    matrix.has_canonical_format = True
    return matrix


@pytest.mark.parametrize("index_dtype", [np.int32, np.int64])
@pytest.mark.parametrize("shape", [(0, 5), (4, 0), (3, 6), (40, 17)])
def test_csc_of_canonical_rows_is_the_constructors(shape: tuple[int, int],
                                                   index_dtype: type) -> None:
    rng = np.random.default_rng(sum(shape))
    dense = sp.csr_array(rng.normal(size=shape) * (rng.random(shape) < 0.3))
    rows = sp.csr_array((dense.data, dense.indices.astype(index_dtype),
                         dense.indptr.astype(index_dtype)), shape=shape)
    assert rows.indices.dtype == index_dtype  # the step QPs' rows come with either
    if rows.nnz:
        rows.data[0] = -0.0  # a stored zero of either sign stays an entry
    assert rows.has_canonical_format
    ours = _sparse.csc_matrix_of(rows)
    assert type(ours) is sp.csc_matrix
    _assert_same(ours, _constructed_csc(rows))
    assert np.array_equal(ours @ np.arange(float(shape[1])), rows @ np.arange(float(shape[1])))


def test_csc_without_a_known_layout_goes_through_the_constructor(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_sparse, "_CSC_TEMPLATE", None)
    rows = sp.csr_array(np.array([[0.0, 2.0], [1.0, 0.0]]))
    _assert_same(_sparse.csc_matrix_of(rows), _constructed_csc(rows))


def test_stacked_blocks_are_scipys_stack() -> None:
    from wuerfel_cvx.solve.adapters._native import RowStack

    rng = np.random.default_rng(3)
    blocks = [sp.csr_array(rng.normal(size=(rows, 7)) * (rng.random((rows, 7)) < 0.4))
              for rows in (0, 3, 5)]
    ours = RowStack([(blocks[0], 1.0, None), (blocks[1], -1.0, None),
                     (blocks[2], 1.0, None)]).matrix
    reference = sp.vstack([blocks[0], -blocks[1], blocks[2]], format="csc")
    assert type(ours) is sp.csc_matrix and ours.has_canonical_format
    assert ours.shape == reference.shape
    assert np.array_equal(ours.toarray(), reference.toarray())
    assert np.array_equal(ours.indptr, reference.indptr)
    assert np.array_equal(ours.indices, reference.indices)


def _kkt_blocks(seed: int) -> tuple[np.ndarray, sp.csr_array, sp.csr_array, np.ndarray]:
    """A diagonal Hessian, equality rows, inequality rows and some tight rows, at random."""
    rng = np.random.default_rng(seed)
    n = 12
    hessian = rng.uniform(0.5, 2.0, n)
    equalities = sp.csr_array(sp.random(3, n, density=0.4, random_state=rng))
    inequalities = sp.csr_array(sp.random(9, n, density=0.3, random_state=rng))
    equalities.sort_indices()
    inequalities.sort_indices()
    return hessian, equalities, inequalities, np.array([7, 1, 4], dtype=np.int64)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_kkt_matrix_is_scipys_block_matrix(seed: int) -> None:
    hessian, equalities, inequalities, tight = _kkt_blocks(seed)
    n = hessian.size
    rows = sp.vstack([equalities, inequalities[tight]])
    expected = sp.block_array([[sp.diags_array(hessian), rows.T], [rows, None]]).toarray()
    indptr, indices, data = _sparse.kkt_matrix(
        np.arange(n + 1), np.arange(n), hessian, equalities.data, equalities.indices,
        equalities.indptr, inequalities.data, inequalities.indices, inequalities.indptr, tight)
    size = indptr.size - 1
    ours = sp.csc_matrix((data, indices, indptr), shape=(size, size))
    assert ours.has_sorted_indices
    assert np.array_equal(ours.toarray(), expected)
    assert np.array_equal(ours.diagonal(), np.concatenate([hessian, np.zeros(size - n)]))
    assert ours.nnz == np.count_nonzero(expected) + size - n  # the rows' zero diagonal


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ldl_solves_a_quasi_definite_system_to_round_off(seed: int) -> None:
    hessian, equalities, inequalities, tight = _kkt_blocks(seed)
    n, m = hessian.size, equalities.shape[0] + tight.size
    indptr, indices, data = _sparse.kkt_matrix(
        np.arange(n + 1), np.arange(n), hessian, equalities.data, equalities.indices,
        equalities.indptr, inequalities.data, inequalities.indices, inequalities.indptr, tight)
    shift = np.concatenate([np.full(m, -0.1), np.zeros(n)])  # rows first: quasi-definite
    new_of_old = np.concatenate([np.arange(m, n + m), np.arange(m)])
    *factor, factored = _sparse.ldl_factor(
        *_sparse.permuted_upper(data, indices, indptr, new_of_old, shift))
    assert factored
    rhs = np.random.default_rng(seed).normal(size=n + m)
    regularised = (sp.csc_matrix((data, indices, indptr), shape=(n + m, n + m)).toarray()
                   + np.diag(shift[new_of_old]))
    solution = _sparse.ldl_solve(*factor, new_of_old, rhs)
    # backward stable: a residual of the order of the unit round-off times |M| |x|
    scale = np.abs(regularised).max() * np.abs(solution).max()
    assert np.abs(regularised @ solution - rhs).max() <= 1e3 * np.finfo(float).eps * scale
