"""A step QP in qpsolvers' form, written and read as a ``qpsolvers.Problem`` ``.npz`` file.

qpsolvers poses every QP as::

    minimise    x' P x / 2 + q' x
    subject to  G x <= h,   A x == b

The step QP (:class:`~wuerfel_cvx.formulations.qp.StepQP`) is taken in that form through
the map PROXQP's native backend already uses
(:func:`wuerfel_cvx.solve.adapters.proxqp.proxsuite_form`:
``P = 2 W + 2 F' F``, ``q = -P t``, ``A = E``, ``b = e``, and ``C``, ``l``, ``u`` with
``C_i = -G_i``, ``u_i = -h_i`` for a one-sided row and ``h_i <= G_i x <= u_i`` for a
two-sided one).  qpsolvers has no two-sided rows, so ``G`` is ``C`` followed by ``-C_i``
for each two-sided row ``i``, and ``h`` is ``u`` followed by ``-l_i``.  The objective drops
the step QP's constant ``t' W t + |F t|^2``.

Files are written as ``qpsolvers.Problem.save`` writes them (keys ``P, q, G, h, A, b, lb,
ub``, absent blocks as ``np.array(None)``), compressed.  Every matrix is stored dense:
``Problem.save`` turns a sparse ``G`` or ``A`` into a 0-d object array with ``np.array``,
which ``Problem.load`` (``allow_pickle=False``) reads back as ``None``, so a sparse block
would not survive the round trip.  ``P`` is not stored sparse either, for the same reason.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...formulations.qp import StepQP
from ...scenes.geometry import FloatArray
from ...solve.adapters.proxqp import proxsuite_form

PROBLEM_KEYS = ("P", "q", "G", "h", "A", "b", "lb", "ub")
"""The arrays of a ``qpsolvers.Problem`` file, in ``Problem.save``'s order."""


@dataclass(frozen=True)
class QPData:
    """A QP in qpsolvers' form, dense: ``min x'Px/2 + q'x  s.t.  G x <= h, A x == b``."""

    P: FloatArray
    """Hessian (kg for the velocity unknowns), symmetric positive definite, ``(n, n)``."""
    q: FloatArray
    """Linear term, ``(n,)``."""
    G: FloatArray | None
    """Inequality rows, ``(m, n)``; ``None`` without any."""
    h: FloatArray | None
    """Their bounds, ``(m,)``."""
    A: FloatArray | None
    """Equality rows, ``(p, n)``; ``None`` without any."""
    b: FloatArray | None
    """Their right-hand sides, ``(p,)``."""

    @property
    def n_variables(self) -> int:
        """Number of unknowns ``n``."""
        return int(self.q.shape[0])

    @property
    def n_inequalities(self) -> int:
        """Rows of ``G`` (a two-sided step QP row counts twice)."""
        return 0 if self.G is None else int(self.G.shape[0])

    @property
    def n_equalities(self) -> int:
        """Rows of ``A``."""
        return 0 if self.A is None else int(self.A.shape[0])

    def arrays(self) -> dict[str, Any]:
        """The arrays of the file, as ``qpsolvers.Problem.save`` writes them."""
        values = {"P": self.P, "q": self.q, "G": self.G, "h": self.h, "A": self.A,
                  "b": self.b, "lb": None, "ub": None}
        return {key: np.array(values[key]) for key in PROBLEM_KEYS}


def qpsolvers_form(qp: StepQP) -> QPData:
    """``qp`` in qpsolvers' form (the module docstring), dense."""
    form, sign = proxsuite_form(qp)
    hessian = np.asarray(form["H"], dtype=np.float64)
    linear = np.asarray(form["g"], dtype=np.float64)
    G = h = None
    if form["C"] is not None:
        rows = np.asarray(form["C"], dtype=np.float64)
        two_sided = np.flatnonzero(sign < 0)
        G = np.vstack([rows, -rows[two_sided]])
        h = np.concatenate([np.asarray(form["u"], dtype=np.float64),
                            -np.asarray(form["l"], dtype=np.float64)[two_sided]])
    A = None if form["A"] is None else np.asarray(form["A"], dtype=np.float64)
    b = None if form["b"] is None else np.asarray(form["b"], dtype=np.float64)
    return QPData(P=hessian, q=linear, G=G, h=h, A=A, b=b)


def save_problem(path: Path, data: QPData) -> Path:
    """Write ``data`` to ``path`` (a ``.npz`` file ``qpsolvers.Problem.load`` reads)."""
    path = path.with_suffix(".npz")
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **data.arrays())
    return path


def load_problem(path: Path) -> QPData:
    """Read a file written by :func:`save_problem` (or ``qpsolvers.Problem.save``).

    Reads as ``qpsolvers.Problem.load`` does (``allow_pickle=False``; an absent block is an
    object array, read as ``None``).
    """
    with np.load(path, allow_pickle=False) as arrays:
        def optional(key: str) -> FloatArray | None:
            try:
                return np.asarray(arrays[key], dtype=np.float64)
            except ValueError:  # an object array: the block is absent
                return None

        P, q = optional("P"), optional("q")
        assert P is not None and q is not None, f"{path} has no objective"
        return QPData(P=P, q=q, G=optional("G"), h=optional("h"), A=optional("A"),
                      b=optional("b"))


def objective_value(data: QPData, x: FloatArray) -> float:
    """``x' P x / 2 + q' x`` (qpsolvers' objective, without the step QP's constant)."""
    return float(0.5 * x @ (data.P @ x) + data.q @ x)
