"""wuerfel_cvx's step QPs as a qpbenchmark test set.

``wuerfel-cvx export-qps`` writes this file beside a ``problems/`` folder of
``qpsolvers.Problem`` files (``.npz``, dense, one per step QP) and a ``problems.csv`` that
names each problem's scene, formulation, step, size, active set and condition estimate.
It needs qpbenchmark only, not wuerfel_cvx.  From its folder::

    qpbenchmark wuerfel_step_qps.py list_problems
    qpbenchmark wuerfel_step_qps.py --results-path wuerfel_step_qps.csv run --author NAME
    python wuerfel_step_qps.py run --author NAME    # the same

Both write the results to ``wuerfel_step_qps.csv`` and qpbenchmark's report to
``wuerfel_step_qps.md`` beside this file.  qpbenchmark's command line keeps results only
where ``--results-path`` says (without it, ``run`` stops when it saves them); run as a
script, this file says where.

Each step QP is ``min sum_i w_i (v_i - t_i)^2`` over the bodies' new velocities, subject
to the rigid bodies' rods (equalities) and speculative contact rows (inequalities, two
per contact with closest-approach rows, two per edge of a friction cone), taken from a
simulation of squares and boxes falling and stacking in 2-D.  What makes them hard:
resting stacks (coincident, linearly dependent active rows), large mass ratios, tables
of 1e6 to 1e12 kg, deep overlaps and friction cones.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import qpbenchmark
from qpbenchmark.benchmark import main

HERE = Path(__file__).resolve().parent
PROBLEMS = HERE / "problems"
"""The problem files (``NAME.npz``; the problem's name is the file's stem)."""
RESULTS = HERE / "wuerfel_step_qps.csv"
"""Where ``python wuerfel_step_qps.py run`` keeps its results."""

TIME_LIMIT = 2.0
"""Seconds per solver call (qpbenchmark's runtime tolerance, and the solvers' own limit
where qpbenchmark or this set can set one).  A step's QP solves in milliseconds; the
limit is there for calls that do not converge."""


class WuerfelStepQps(qpbenchmark.TestSet):  # type: ignore[misc]  # an untyped base
    """Step QPs of wuerfel_cvx's benchmark scenes, one ``.npz`` file each."""

    @property
    def description(self) -> str:
        """Test set description."""
        return ("Step QPs of rigid squares and boxes in 2-D (wuerfel_cvx): resting stacks, "
                "pyramids, rain, mass ratio 1000, heavy tables of 1e6 to 1e12 kg, deep "
                "overlap and friction cones, each named by scene, formulation, step and "
                "what makes it hard.")

    @property
    def title(self) -> str:
        """Report title."""
        return "wuerfel_cvx step QPs"

    @property
    def sparse_only(self) -> bool:
        """Dense solvers (DAQP, quadprog) take part too: the QPs are small."""
        return False

    def define_tolerances(self, runtime: float = TIME_LIMIT) -> None:
        """The tolerances of qpbenchmark, with this set's time limit."""
        super().define_tolerances(runtime=runtime)

    def define_solver_settings(self) -> None:
        """The settings of qpbenchmark, with Clarabel's own time limit set too."""
        super().define_solver_settings()
        for name, settings in self.solver_settings.items():
            settings.set_param("clarabel", "time_limit", self.tolerances[name].runtime)

    def __iter__(self) -> Iterator[qpbenchmark.Problem]:
        """The problems, in the order of their names."""
        for path in sorted(PROBLEMS.glob("*.npz")):
            yield qpbenchmark.Problem.load(str(path))


if __name__ == "__main__":
    main(test_set_path=__file__, results_path=RESULTS)
