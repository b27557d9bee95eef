"""The preload of a sweep's ``LocalCluster`` workers (:mod:`wuerfel_cvx.lab.bench.dask_sweep`).

Each worker process imports this module as it starts: the runner with it (cvxpy and the
solvers), all at once rather than on each worker's first point, and :func:`dask_setup`
leaves Ctrl-C to the process that runs the sweep.  A terminal sends Ctrl-C to every process
of the command; a worker that took it would die with asyncio's traceback while the sweep
closes the cluster, which ends the workers itself.
"""

from __future__ import annotations

from . import runner  # noqa: F401 - imported as the worker starts
from .ctrl_c import ignore_ctrl_c


def dask_setup(worker: object) -> None:
    """Dask's preload hook, called in the worker as it starts: ignore Ctrl-C."""
    ignore_ctrl_c()
