"""Run a suite: references first, then grid points, rows appended as they finish.

The results file is ``<out>/results.csv`` (see :mod:`wuerfel_cvx.lab.bench.schema`).  A sweep
that is interrupted, even killed mid-write, resumes: rows already in the file are skipped,
a partial last line is cut off, references already computed (``<out>/references/``) are
reused.  Per-step series go to ``<out>/series/``.  With ``jobs > 1`` the work runs in that
many worker processes, with ``dask`` on a Dask cluster (:mod:`wuerfel_cvx.lab.bench.dask_sweep`);
either way only the main process writes the results file, and the rows are the same.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable, Generator, Iterable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import AbstractContextManager, closing, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from tqdm.auto import tqdm

from ...__main__ import relayed_presses
from ...errors import InputError
from ...scenes.scene import Scene
from ...solve.registry import SOLVERS, available_solvers
from ...versions import code_version
from ..peers import PEER_ENGINES, available_peers
from ..robustness.determinism import physics_fingerprint
from . import schema
from .ctrl_c import held_ctrl_c, ignore_ctrl_c
from .runner import (
    Reference,
    load_reference,
    reference_file_name,
    run_point,
    run_reference,
    save_reference,
)
from .suite import REFERENCE_REFINEMENT, GridPoint, ReferenceKey, Suite

if TYPE_CHECKING:
    from .dask_sweep import DaskCluster

RESULTS_FILE = "results.csv"

ReferenceKeys = Generator[ReferenceKey, None, None]
"""What an executor yields for the references: each key once its reference is saved."""
Rows = Generator[tuple[GridPoint, dict[str, Any]], None, None]
"""What an executor yields for the grid points: each point with its row, as it finishes."""


@dataclass(frozen=True)
class SweepSummary:
    """What a sweep did."""

    results: Path
    """The results CSV."""
    ran: int
    """Grid points run now."""
    skipped_done: int
    """Grid points already in the results file."""
    skipped_unavailable: tuple[str, ...]
    """Point ids left out because their solver or peer engine is not installed."""
    failed: int
    """Rows written now with status ``failed`` or ``error``."""


def run_sweep(suite: Suite, out: str | Path, *, jobs: int = 1, progress: bool | None = None,
              echo: Callable[[str], None] | None = None,
              dask: DaskCluster | None = None) -> SweepSummary:
    """Run every grid point of ``suite`` not yet in ``out/results.csv``.

    ``progress=None`` shows a bar only when standard error is a terminal.  ``echo`` gets
    one-line notes (skipped solvers, resumed rows, the Dask dashboard); default: print to
    standard error.  ``dask`` runs the points on a Dask cluster instead of ``jobs`` local
    processes.
    """
    if jobs < 1:
        raise InputError(f"must be at least 1, got {jobs}", field="--jobs")
    if dask is not None and jobs != 1:
        raise InputError("give --jobs or a Dask cluster (--dask, --scheduler), not both",
                         field="--jobs")
    note = echo or (lambda text: print(text, file=sys.stderr))
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create ({exc.strerror})", source=str(out),
                         field="--out") from None
    results = out / RESULTS_FILE
    done = _finished_ids(results, suite.name)
    runnable, unavailable = _split_available(suite.points)
    for message in suite.skipped:
        note(message)
    for point_id in unavailable:
        note(f"skipped (not installed): {point_id}")
    todo = [p for p in runnable if p.point_id not in done]
    if done:
        note(f"resuming {results}: {len(runnable) - len(todo)} of {len(runnable)} rows done")
    if todo:
        record_provenance(out / schema.PROVENANCE_FILE)
    references = _references_needed(todo, out)
    show = sys.stderr.isatty() if progress is None else progress
    work = sum(key_steps(key) for key in references) + sum(p.steps for p in todo)
    failed = 0
    with _executor(jobs, dask if todo else None, note) as executor, \
            tqdm(total=work, unit="step", disable=not show, desc=suite.name,
                 dynamic_ncols=True) as bar:
        # closing: on Ctrl-C the executor stops its workers now, not when collected
        with closing(executor.references(references)) as keys:
            for key in keys:
                bar.update(key_steps(key))
        with closing(executor.points(todo, out)) as rows:
            for point, row in rows:
                schema.append_row(results, row)
                failed += row["status"] != "ok"
                bar.update(point.steps)
    return SweepSummary(results, len(todo), len(runnable) - len(todo), tuple(unavailable),
                        failed)


class Executor(Protocol):
    """Where a sweep's references and grid points run; :func:`run_sweep` writes the rows."""

    def references(self, needed: dict[ReferenceKey, Path]) -> ReferenceKeys:
        """Compute each reference and save it to its path; yield its key once saved."""

    def points(self, todo: list[GridPoint],
               out: Path) -> Rows:
        """Run each point, its series written under ``out/series``; yield its row."""


@dataclass(frozen=True)
class ProcessPool:
    """The sweep in this process (``jobs == 1``) or in ``jobs`` local worker processes."""

    jobs: int

    def references(self, needed: dict[ReferenceKey, Path]) -> ReferenceKeys:
        """Compute each reference in a worker, which saves it; yield its key."""
        for key, _ in _run_all(_reference_tasks(needed), self.jobs):
            yield key

    def points(self, todo: list[GridPoint],
               out: Path) -> Rows:
        """Run each point in a worker, which writes its series; yield its row."""
        yield from _run_all(_point_tasks(todo, out), self.jobs)


def _executor(jobs: int, dask: DaskCluster | None,
              note: Callable[[str], None]) -> AbstractContextManager[Executor]:
    if dask is None:
        return nullcontext(ProcessPool(jobs))
    from .dask_sweep import dask_executor

    return dask_executor(dask, note)


def record_provenance(path: Path) -> dict[str, Any]:
    """Record (or check) what physics and code a results directory's rows come from.

    The physics fingerprint (:func:`~wuerfel_cvx.lab.robustness.determinism.physics_fingerprint`,
    the golden runs run now) must equal the one recorded when the directory's first rows
    were measured: rows of two physics in one results file would compare apples with
    pears, so a resumed sweep on changed physics is an :class:`InputError`.  Each code
    version (:func:`~wuerfel_cvx.versions.code_version`) that added rows is listed.
    """
    fingerprint, code = physics_fingerprint(), code_version()
    recorded: dict[str, Any] = ({"physics_fingerprint": fingerprint, "code_versions": []}
                                if not path.exists() else json.loads(path.read_text()))
    if recorded.get("physics_fingerprint") != fingerprint:
        raise InputError(f"its rows were measured on physics fingerprint "
                         f"{recorded.get('physics_fingerprint')}, this code's is {fingerprint}: "
                         "use a new --out (or delete the directory)", source=str(path.parent))
    if code not in recorded["code_versions"]:
        recorded["code_versions"].append(code)
    path.write_text(json.dumps(recorded, indent=1) + "\n", encoding="utf-8")
    return recorded


def key_steps(key: ReferenceKey) -> int:
    """Fine steps of a reference run (its share of the progress bar)."""
    _, _, dt, duration, _ = key
    return max(1, round(duration / dt)) * REFERENCE_REFINEMENT


def _finished_ids(results: Path, suite: str) -> set[str]:
    if not results.exists():
        return set()
    schema.repair(results)
    frame = schema.read_results(results, upgrade=False)
    suites = set(frame["suite"].dropna().unique())
    if suites - {suite}:
        raise InputError(f"holds results of suite(s) {sorted(suites)}, not '{suite}'; "
                         "use another --out", source=str(results))
    ids = list(frame["point_id"].dropna())
    return set(ids)


def _split_available(points: Iterable[GridPoint]) -> tuple[list[GridPoint], list[str]]:
    installed = set(available_solvers()) | set(available_peers())
    runnable, unavailable = [], []
    for point in points:
        known = point.solver in SOLVERS or point.solver in PEER_ENGINES
        if known and point.solver not in installed:
            unavailable.append(point.point_id)
        else:  # installed, or an unknown name that will become an error row
            runnable.append(point)
    return runnable, unavailable


def _references_needed(points: Iterable[GridPoint],
                       out: Path) -> dict[ReferenceKey, Path]:
    needed = {}
    for point in points:
        key = point.reference_key
        if key is not None:
            path = out / "references" / reference_file_name(key)
            if not path.exists():
                needed[key] = path
    return needed


Task = tuple[Any, Callable[..., Any], tuple[Any, ...]]


def _reference_tasks(references: dict[ReferenceKey, Path]) -> list[Task]:
    return [(key, _reference_job, (key, path)) for key, path in references.items()]


def _point_tasks(points: list[GridPoint], out: Path) -> list[Task]:
    return [(point, _point_job, (point, out)) for point in longest_first(points)]


def longest_first(points: Iterable[GridPoint]) -> list[GridPoint]:
    """The points in the order they are started: most steps first, for a short tail."""
    return sorted(points, key=lambda point: point.steps, reverse=True)


def try_reference(key: ReferenceKey, scene: Scene | None = None) -> Reference | None:
    """:func:`run_reference`, or ``None`` if it raises (e.g. an unknown scene).

    Its grid points then report the error themselves.
    """
    try:
        return run_reference(key, scene)
    except Exception:
        return None


def point_reference(point: GridPoint, out: Path) -> Reference | None:
    """The point's reference as saved under ``out/references``; ``None`` if it needs none."""
    key = point.reference_key
    if key is None:
        return None
    path = out / "references" / reference_file_name(key)
    if path.exists():
        return load_reference(path)
    return Reference(np.zeros((0, 0, 2)), complete=False, detail="not computed")


def _reference_job(key: ReferenceKey, path: Path) -> Path:
    reference = try_reference(key)
    if reference is not None:
        save_reference(reference, path)
    return path


def _point_job(point: GridPoint, out: Path) -> dict[str, Any]:
    return run_point(point, point_reference(point, out), out / "series")


def _run_all(tasks: list[Task], jobs: int) -> Generator[tuple[Any, Any], None, None]:
    """Yield ``(label, result)`` as tasks finish, in this process or in ``jobs`` workers.

    The workers ignore Ctrl-C (a terminal sends it to them too); this process takes it,
    stops them at once and raises :class:`KeyboardInterrupt`, so a point cut short
    leaves no row and no process behind.
    """
    if jobs == 1 or len(tasks) <= 1:
        for label, function, args in tasks:
            presses = relayed_presses()
            result = function(*args)
            if presses is not None and relayed_presses() != presses:
                # a Ctrl-C the task's solver took (and answered anyway, or failed on):
                # the point was cut short, so it leaves no row
                raise KeyboardInterrupt
            yield label, result
        return
    pool = ProcessPoolExecutor(max_workers=jobs, initializer=ignore_ctrl_c)
    try:
        pending: dict[Future[Any], Any] = {pool.submit(function, *args): label
                                           for label, function, args in tasks}
        while pending:
            # with a timeout: a Ctrl-C relayed to this thread (wuerfel_cvx.__main__) is
            # acted on within it, not only when the next point finishes
            finished, _ = wait(pending, timeout=WAIT_POLL, return_when=FIRST_COMPLETED)
            for future in finished:
                yield pending.pop(future), future.result()
    except BaseException:  # Ctrl-C, a failed task, or the consumer stopping early
        with held_ctrl_c():  # a second Ctrl-C must not leave workers behind
            _stop_workers(pool)
        raise
    pool.shutdown()


WAIT_POLL = 0.2
"""Seconds between looks for a Ctrl-C while waiting for the workers."""


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel what has not started and end the workers now, waiting for each to exit."""
    # ProcessPoolExecutor has no public way to end busy workers before Python 3.14
    # (terminate_workers); their processes are the executor's ``_processes``.
    workers = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for worker in workers:
        worker.terminate()
    for worker in workers:
        worker.join(timeout=10)
