"""A sweep's grid points on a Dask cluster: a ``LocalCluster`` of N workers, or a scheduler.

The sweep itself (:func:`wuerfel_cvx.lab.bench.sweep.run_sweep`) is the same as on the process
pool: the same points in the same order, one writer (this process) appending and fsyncing
each row as it arrives, the same resume.  What differs is where the points run and what
travels:

- A worker gets everything as data: the grid point, its scene (a :class:`~wuerfel_cvx.Scene`
  resolved here, so a scene file on this machine's disk need not exist on the worker's) and
  its dt/8 reference.  It writes nothing; it returns the row and the per-step series, and
  this process writes both (references too: a worker returns the reference run, this
  process saves it under ``<out>/references``).
- A worker killed mid-sweep loses nothing: a row is written only when its point's result
  has arrived here, and the scheduler reruns the dead worker's points elsewhere.  A point
  whose workers die more often than ``distributed.scheduler.allowed-failures`` (a crash of
  the point itself, not of the machine) becomes an error row naming ``KilledWorker``, as
  every other failure of a point does; a reference that does is "not computed" for its
  points.  Any
  other failure of a task is the cluster's (say, a worker without this package): it stops
  the sweep, and the rows written so far stay for the resume.

``dask[distributed]`` is the ``dask`` extra; without it, asking for a cluster is an
:class:`~wuerfel_cvx.errors.InputError` naming the extra.
"""

from __future__ import annotations

import logging
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ...errors import InputError
from ...scenes.scene import Scene
from ...simulate import resolve_scene
from .ctrl_c import held_ctrl_c
from .runner import PointResult, error_row, measure_point, save_reference, write_series
from .suite import GridPoint, ReferenceKey
from .sweep import ReferenceKeys, Rows, longest_first, point_reference, try_reference

if TYPE_CHECKING:
    from distributed import Client, Future, LocalCluster

EXTRA = "dask"
"""The optional dependency group that installs ``dask[distributed]``."""

PRELOAD = "wuerfel_cvx.lab.bench.dask_worker"
"""The module a ``LocalCluster``'s workers import as they start: the runner (cvxpy and the
solvers with it) all at once rather than on each worker's first point, and Ctrl-C left to
this process (:mod:`wuerfel_cvx.lab.bench.dask_worker`)."""


@dataclass(frozen=True)
class DaskCluster:
    """Where a sweep runs on Dask: a new ``LocalCluster``, or an existing scheduler."""

    workers: int | None = None
    """Worker processes of a ``LocalCluster`` started for the sweep (one thread each)."""
    scheduler: str | None = None
    """Address of a running scheduler to join, e.g. ``tcp://10.0.0.5:8786``."""

    def __post_init__(self) -> None:
        if (self.workers is None) == (self.scheduler is None):
            raise InputError("give either a number of workers or a scheduler address",
                             field="--dask")
        if self.workers is not None and self.workers < 1:
            raise InputError(f"must be at least 1, got {self.workers}", field="--dask")
        if self.scheduler is not None and not self.scheduler.strip():
            raise InputError("needs an address, e.g. tcp://host:8786", field="--scheduler")

    @property
    def option(self) -> str:
        """The command-line option that asked for this cluster (for error messages)."""
        return "--dask" if self.workers is not None else "--scheduler"


def require_distributed(option: str = "--dask") -> None:
    """Raise an :class:`InputError` naming the extra to install if ``distributed`` is missing."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise InputError(f"needs Dask: pip install \"wuerfel_cvx[{EXTRA}]\" "
                         "(dask[distributed])", field=option) from None


@contextmanager
def dask_executor(cluster: DaskCluster,
                  note: Callable[[str], None]) -> Iterator[DaskExecutor]:
    """Start (or join) the cluster, say where its dashboard is, and close it afterwards.

    Starting and closing are not cut short by Ctrl-C (a cluster half started cannot be
    closed cleanly, :func:`~wuerfel_cvx.lab.bench.ctrl_c.held_ctrl_c`); a Ctrl-C while it
    starts stops the sweep once it has.
    """
    require_distributed(cluster.option)
    _start_resource_tracker()
    failure: Exception | None = None
    with held_ctrl_c() as pressed:
        try:
            local, client = _start(cluster)
        except Exception as exc:  # raised below, unless the Ctrl-C caused it
            failure = exc
    if failure is not None:
        if pressed.is_set():  # a worker that took the Ctrl-C as it started
            raise KeyboardInterrupt from None
        raise failure
    try:
        if pressed.is_set():
            raise KeyboardInterrupt
        yield _ready(client, note)
    finally:
        with held_ctrl_c():
            client.close()
            if local is not None:
                local.close()


def _start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker from this thread, its signal mask kept.

    Starting it unblocks SIGINT in the thread that does (``resource_tracker.ensure_running``
    in CPython); left to the cluster's first worker process, that is a thread of Dask's,
    which would then take the Ctrl-C that the command line's relay must get
    (:mod:`wuerfel_cvx.__main__`).  Once it runs, later starts leave every mask alone.
    """
    from multiprocessing import resource_tracker

    mask = signal.pthread_sigmask(signal.SIG_BLOCK, ())  # the current mask, unchanged
    resource_tracker.ensure_running()
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _start(cluster: DaskCluster) -> tuple[LocalCluster | None, Client]:
    """A new ``LocalCluster`` and its client, or a client of the running scheduler."""
    from distributed import Client, LocalCluster

    if cluster.workers is None:
        return None, _connect(cluster)
    # CRITICAL: a worker busy with a point when a Ctrl-C closes the cluster loses its
    # scheduler and logs that as an ERROR with a traceback; a failed point or task is
    # reported by the sweep itself (an error row, or the task's exception)
    local = LocalCluster(n_workers=cluster.workers, threads_per_worker=1, processes=True,
                         dashboard_address=":0", silence_logs=logging.CRITICAL,
                         preload=[PRELOAD])
    try:
        return local, Client(local)
    except BaseException:
        local.close()
        raise


def _connect(cluster: DaskCluster) -> Client:
    """A client of the running scheduler at ``cluster.scheduler``."""
    from distributed import Client

    assert cluster.scheduler is not None
    try:
        return Client(cluster.scheduler)
    except (OSError, ValueError, TypeError) as exc:  # unreachable, or not an address
        raise InputError(f"cannot connect ({exc})", source=cluster.scheduler,
                         field="--scheduler") from None


def _ready(client: Client, note: Callable[[str], None]) -> DaskExecutor:
    info = client.scheduler_info()
    note(f"dask: {len(client.nthreads())} workers at {info.get('address', '?')}")
    if "dashboard" in info.get("services", {}):
        note(f"dask dashboard: {client.dashboard_link}")
    return DaskExecutor(client)


@dataclass
class DaskExecutor:
    """The sweep's work as Dask futures; results are written here, as they arrive."""

    client: Client
    _scenes: dict[str, Scene | None] = field(default_factory=dict)

    def references(self, needed: dict[ReferenceKey, Path]) -> ReferenceKeys:
        """Run each reference on a worker; save it here as it arrives, and yield its key."""
        from distributed import as_completed

        futures = {self.client.submit(try_reference, key, self._scene(key[0]), pure=False):
                   (key, path) for key, path in needed.items()}
        for future in as_completed(futures):
            key, path = futures.pop(future)
            reference = None  # none: its points say "not computed"
            if future.status == "finished":
                reference = future.result()
            else:
                _killed_worker(future)  # raises a failure that is not a KilledWorker
            if reference is not None:
                save_reference(reference, path)
            yield key

    def points(self, todo: list[GridPoint],
               out: Path) -> Rows:
        """Run each point on a worker; write its series here, and yield its row."""
        from distributed import as_completed

        futures = {self.client.submit(measure_point, point, point_reference(point, out),
                                      self._scene(point.scene_input), pure=False): point
                   for point in longest_first(todo)}
        for future in as_completed(futures):
            point = futures.pop(future)
            result = _point_result(future, point)
            write_series(result, out / "series")
            yield point, result.row

    def _scene(self, name: str) -> Scene | None:
        """The scene resolved here, or ``None`` if it cannot be (the point reports why)."""
        if name not in self._scenes:
            try:
                self._scenes[name] = resolve_scene(name)
            except Exception:
                self._scenes[name] = None
        return self._scenes[name]


def _point_result(future: Future[PointResult], point: GridPoint) -> PointResult:
    """The point's result, or its error row when its workers kept dying (``KilledWorker``).

    Any other failure of the task (a worker without this package, say) is the cluster's,
    not the point's: it stops the sweep, which resumes once the cluster is mended.
    """
    if future.status == "finished":
        return future.result()
    return PointResult(error_row(point, _killed_worker(future)), None)


def _killed_worker(future: Future[Any]) -> BaseException:
    """The ``KilledWorker`` a failed task ended with; re-raises any other failure."""
    from distributed import KilledWorker

    failure = future.exception() if future.status == "error" else None
    if not isinstance(failure, KilledWorker):
        future.result()  # raises the task's own exception, or a CancelledError
        raise RuntimeError(f"a Dask task ended '{future.status}'")  # pragma: no cover
    return failure
