"""What a step's time is judged against: one factorization of its QP's KKT system.

Every exact second-order method (an interior-point iteration, OSQP's ADMM with its direct
solver, an active-set polish) factors a KKT matrix of the step's QP at least once a step,
so one numeric factorization of it is the floor of any such step.  The matrix is OSQP's
form, with every row of the QP: ``[[P + sigma I, A'], [A, -I / rho]]`` (``sigma`` and
``rho`` OSQP's defaults), factored ``L D L'`` by QDLDL (OSQP's own factorization; the
``qdldl`` package comes with cvxpy) after its AMD ordering, which a solver finds once per
pattern and which is left out of the time.
"""

from __future__ import annotations

import statistics
import time

import numpy as np
import qdldl
import scipy.sparse as sp

from ...formulations import StepQP
from ...solve.kkt import ActiveSet, reduced_kkt

SIGMA = 1e-6
"""OSQP's default regularisation of the unknowns' block."""
RHO = 0.1
"""OSQP's default step size: the rows' block is ``-I / rho``."""
REPEATS = 3
"""Numeric factorizations timed; the median is reported."""


def full_kkt_matrix(qp: StepQP) -> sp.csc_matrix:
    """The upper triangle of ``qp``'s KKT matrix with every row, OSQP's form (CSC)."""
    every_row = ActiveSet(np.arange(qp.n_inequalities, dtype=np.int64),
                          np.zeros(0, dtype=np.int64))
    matrix, _ = reduced_kkt(qp, every_row)
    rows = matrix.shape[0] - qp.n_variables
    diagonal = np.concatenate([np.full(qp.n_variables, SIGMA), np.full(rows, -1.0 / RHO)])
    upper: sp.csc_matrix = sp.triu(matrix + sp.diags_array(diagonal), format="csc")
    return upper


def kkt_factorization_seconds(qp: StepQP, repeats: int = REPEATS) -> float:
    """Median wall time (s) of one numeric factorization of :func:`full_kkt_matrix`."""
    matrix = full_kkt_matrix(qp)
    solver = qdldl.Solver(matrix, upper=True)  # the ordering and a first factor: not timed
    seconds = []
    for _ in range(repeats):
        started = time.perf_counter()
        solver.update(matrix, upper=True)
        seconds.append(time.perf_counter() - started)
    return statistics.median(seconds)
