"""Run a suite: references first, then grid points, rows appended as they finish.

The results file is ``<out>/results.csv`` (see :mod:`wuerfel_cvx.bench.schema`).  A sweep
that is interrupted, even killed mid-write, resumes: rows already in the file are skipped,
a partial last line is cut off, references already computed (``<out>/references/``) are
reused.  Per-step series go to ``<out>/series/``.  With ``jobs > 1`` the work runs in that
many worker processes; only the main process writes the results file.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from ..errors import InputError
from ..peers import PEER_ENGINES, available_peers
from ..solvers import SOLVERS, available_solvers
from . import schema
from .runner import Reference, compute_reference, load_reference, reference_file_name, run_point
from .suite import REFERENCE_REFINEMENT, GridPoint, ReferenceKey, Suite

RESULTS_FILE = "results.csv"


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
              echo: Callable[[str], None] | None = None) -> SweepSummary:
    """Run every grid point of ``suite`` not yet in ``out/results.csv``.

    ``progress=None`` shows a bar only when standard error is a terminal.  ``echo`` gets
    one-line notes (skipped solvers, resumed rows); default: print to standard error.
    """
    if jobs < 1:
        raise InputError(f"must be at least 1, got {jobs}", field="--jobs")
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
    references = _references_needed(todo, out)
    show = sys.stderr.isatty() if progress is None else progress
    work = sum(key_steps(key) for key in references) + sum(p.steps for p in todo)
    failed = 0
    with tqdm(total=work, unit="step", disable=not show, desc=suite.name,
              dynamic_ncols=True) as bar:
        for key, _ in _run_all(_reference_tasks(references), jobs):
            bar.update(key_steps(key))
        for point, row in _run_all(_point_tasks(todo, out), jobs):
            schema.append_row(results, row)
            failed += row["status"] != "ok"
            bar.update(point.steps)
    return SweepSummary(results, len(todo), len(runnable) - len(todo), tuple(unavailable),
                        failed)


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
    longest_first = sorted(points, key=lambda point: point.steps, reverse=True)
    return [(point, _point_job, (point, out)) for point in longest_first]


def _reference_job(key: ReferenceKey, path: Path) -> Path:
    try:
        return compute_reference(key, path)
    except Exception:  # e.g. an unknown scene: its grid points report the error
        return path


def _point_job(point: GridPoint, out: Path) -> dict[str, Any]:
    reference = None
    key = point.reference_key
    if key is not None:
        path = out / "references" / reference_file_name(key)
        reference = (load_reference(path) if path.exists() else
                     Reference(np.zeros((0, 0, 2)), complete=False, detail="not computed"))
    return run_point(point, reference, out / "series")


def _run_all(tasks: list[Task], jobs: int) -> Iterator[tuple[Any, Any]]:
    """Yield ``(label, result)`` as tasks finish, in this process or in ``jobs`` workers."""
    if jobs == 1 or len(tasks) <= 1:
        for label, function, args in tasks:
            yield label, function(*args)
        return
    with ProcessPoolExecutor(max_workers=jobs) as pool:
        pending: dict[Future[Any], Any] = {pool.submit(function, *args): label
                                           for label, function, args in tasks}
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in finished:
                yield pending.pop(future), future.result()
