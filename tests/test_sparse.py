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


def _assert_same(ours: sp.csr_array, theirs: sp.csr_array) -> None:
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
