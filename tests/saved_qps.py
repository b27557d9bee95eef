"""Step QPs saved as ``.npz`` files (test fixtures): written by the fixture scripts, read by tests.

A file holds one step QP ``min sum w (x - t)^2  s.t.  E x == e,  G x >= h`` (no coupling
cost, one-sided rows) as ``weights``, ``target``, ``eq_rhs``, ``ineq_rhs``, ``E`` and ``G``
in COO form (``eq_row``, ``eq_col``, ``eq_data``, ``eq_shape``; ``ineq_*`` likewise) and a
``note`` saying where it came from.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp

from wuerfel_cvx.formulations import StepQP, declare_qp
from wuerfel_cvx.step.contacts import Contacts


def save_qp(qp: StepQP, path: Path, note: str) -> None:
    """Write ``qp``'s data to ``path`` (compressed)."""
    assert qp.cost_factor is None and not qp.upper_rows.size and qp.linear is None
    arrays: dict[str, np.ndarray] = {"weights": qp.weights, "target": qp.target,
                                     "eq_rhs": qp.eq_rhs, "ineq_rhs": qp.ineq_rhs,
                                     "note": np.array(note)}
    for prefix, matrix in (("eq", qp.eq_matrix), ("ineq", qp.ineq_matrix)):
        coo = sp.coo_array(matrix)
        arrays |= {f"{prefix}_row": coo.row, f"{prefix}_col": coo.col,
                   f"{prefix}_data": coo.data, f"{prefix}_shape": np.array(coo.shape)}
    np.savez_compressed(path, **arrays)


def load_qp(path: Path) -> StepQP:
    """The step QP saved at ``path`` (no contacts are kept: the rows are the data)."""
    data = np.load(path)
    eq, ineq = (sp.csr_array((data[f"{k}_data"], (data[f"{k}_row"], data[f"{k}_col"])),
                             shape=tuple(data[f"{k}_shape"])) for k in ("eq", "ineq"))
    return declare_qp(data["weights"], data["target"], eq, data["eq_rhs"], ineq,
                      data["ineq_rhs"], Contacts.empty())
