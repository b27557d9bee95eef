"""The ``wuerfel-cvx`` command line.

``wuerfel-cvx simulate SCENE ...`` runs a simulation and prints a summary;
``wuerfel-cvx bench --suite NAME`` runs a benchmark suite into a results CSV and
``wuerfel-cvx report RESULTS.csv`` turns one into ``reports/<suite>/README.md``;
``wuerfel-cvx robustness`` checks generated and fuzzed scenes and solver faults (its report
goes to ``bench-results/robustness.md``, or with ``--report`` to ``reports/robustness.md``);
``wuerfel-cvx scenes`` lists the named scenes; ``wuerfel-cvx solvers`` lists the
installed solvers.  Bad input ends with one line on standard error and exit status 2;
a failed step ends with status 1, and Ctrl-C with status 130, after saving (and
animating) the steps computed so far.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TextIO

from tqdm.auto import tqdm

from .__main__ import INTERRUPTED, PROG
from ._cli_parser import build_parser
from .errors import InputError, Interrupted, StepFailure
from .friction.forces import body_friction
from .scenes.library import ENTRIES
from .scenes.scene import Scene
from .settings import Settings
from .simulate import resolve_scene, simulate
from .solve.registry import SOLVERS, available_solvers
from .step.sleep import SleepSettings
from .trajectory import Trajectory


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    with warnings.catch_warnings():  # put back as they were when the command ends
        warnings.showwarning = _show_warning
        return _run(argv)


def _show_warning(message: Warning | str, category: type[Warning], filename: str,
                  lineno: int, file: TextIO | None = None, line: str | None = None) -> None:
    """A warning as one line, above a progress bar (not Python's file, line and source)."""
    text = " ".join(str(message).split())
    tqdm.write(f"{PROG}: warning: {text}", file=sys.stderr)


def _run(argv: Sequence[str] | None) -> int:
    """The command of ``argv``; its exit status."""
    try:
        args = build_parser(__doc__.splitlines()[0]).parse_args(argv)
        if args.command == "scenes":
            width = max(len(entry.pattern) for entry in ENTRIES)
            for entry in ENTRIES:
                print(f"{entry.pattern:<{width}}  {entry.description}")
            return 0
        if args.command == "solvers":
            for name in available_solvers():
                print(f"{name:<9} {SOLVERS[name].kind}")
            return 0
        if args.command == "bench":
            return _bench(args)
        if args.command == "report":
            return _report(args)
        if args.command == "robustness":
            return _robustness(args, argv)
        if args.command == "export-qps":
            return _export_qps(args)
        return _simulate(args)
    except InputError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # outside a run's steps (those keep theirs: Interrupted)
        print(f"{PROG}: interrupted", file=sys.stderr)
        return INTERRUPTED


def _simulate(args: argparse.Namespace) -> int:
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    args.out = _out_file(args.out, args.scene)
    _check_outputs(args)  # a bad --out, --animate or --fps is reported before the run
    scene = resolve_scene(args.scene)
    for note in _notes(scene, args):
        print(f"{PROG}: note: {note}", file=sys.stderr)
    try:
        settings = Settings(dt=args.dt, solver=args.solver, formulation=args.formulation,
                            tol=args.tol, solve_path=args.solve_path, polish=args.polish,
                            friction_model=args.friction_model, table_mass=args.table_mass,
                            sleep=SleepSettings() if args.sleep else None,
                            islands=args.islands, fallback=tuple(args.fallback))
        trajectory = simulate(scene, steps=args.steps, progress=progress, settings=settings)
    except StepFailure as failure:
        print(f"{PROG}: {failure}", file=sys.stderr)
        _keep_partial(failure.trajectory, args, progress, "before it")
        return 1
    except Interrupted as stop:
        where = _keep_partial(stop.trajectory, args, progress, "done")
        if stop.trajectory is None or stop.trajectory.n_steps == 0:
            kept = "kept no steps"
        else:
            kept = f"kept the {_count(stop.trajectory.n_steps, 'step')} done " + (
                f"in {where}" if where else "(no --out or --animate to keep them in)")
        print(f"{PROG}: interrupted during step {stop.step} of {args.steps}; {kept}",
              file=sys.stderr)
        return INTERRUPTED
    print(trajectory.summary())
    if (line := fallback_line(trajectory)) is not None:
        print(line)
    if args.out:
        path = _save(trajectory, args.out)
        print(f"saved {path} and {trajectory.metrics_path(path)}")
    if args.animate:
        print(f"wrote {_animate(trajectory, args, progress)}")
    return 0



def _notes(scene: Scene, args: argparse.Namespace) -> list[str]:
    """What the run will not do although the options might suggest it (one line each)."""
    notes = []
    if args.friction_model is not None and not (body_friction(scene) > 0).any():
        notes.append(f"scene {scene.name} has no friction: --friction-model "
                     f"{args.friction_model} changes nothing")
    if args.table_mass is not None:
        notes.append(f"--table-mass {args.table_mass:g}: the table corners are variables of "
                     f"that mass held still by equalities; the tables do not move")
    return notes


def fallback_line(trajectory: Trajectory) -> str | None:
    """The summary's line on steps a fallback solver rescued; ``None`` if there were none.

    A step of several QPs (islands, passes) solved partly by each solver shows as
    ``A+B``, which the line explains.
    """
    metrics = trajectory.metrics
    rescued = metrics["status"] != metrics["primary_status"]
    if not rescued.any():
        return None
    solvers = sorted(set(metrics["solver"][rescued]))
    line = (f"fallback             {_count(int(rescued.sum()), 'step')} solved by "
            f"{', '.join(solvers)} after {trajectory.info['solver']} failed")
    shared = next((name for name in solvers if "+" in name), None)
    if shared is not None:
        line += f" ({shared}: a step whose QPs were solved partly by each)"
    return line


def _out_file(out: str | None, scene: str) -> str | None:
    """``--out`` as a file: a folder (ending in a separator, or existing) gets the scene's name.

    A path that names a ``.npz`` file is taken as one, even where a folder of that name
    exists (which :func:`_check_outputs` then refuses).
    """
    if out is None:
        return None
    folder = out.endswith(("/", os.sep)) or (Path(out).is_dir() and Path(out).suffix != ".npz")
    if not folder:
        return out
    name = Path(scene).stem if scene.endswith(".toml") or "/" in scene else scene
    return str(Path(out) / f"{name}.npz")


def _count(n: int, noun: str) -> str:
    """``n`` and ``noun``, plural unless ``n`` is 1: "1 step", "330 steps"."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def _check_outputs(args: argparse.Namespace) -> None:
    """Raise :class:`InputError` now for outputs that could only fail after the run."""
    if args.out:
        npz = Trajectory.npz_path(args.out)
        for path in (npz, Trajectory.metrics_path(npz)):
            _check_writable(path, source=args.out, field="--out")
    if args.animate:
        from .animation import animation_writer, check_frame_rate

        check_frame_rate(args.fps, field="--fps")
        animation_writer(args.animate)  # a bad suffix or a missing ffmpeg
        _check_writable(Path(args.animate), source=args.animate, field="--animate")


def _check_writable(path: Path, source: str, field: str) -> None:
    """Create ``path``'s folder and open ``path`` for writing (removed again if new)."""
    existed = path.exists()
    blocking = next((folder for folder in path.parents if folder.exists()), None)
    if blocking is not None and not blocking.is_dir():
        raise InputError(f"cannot write ({blocking} is a file, not a folder)", source=source,
                         field=field)
    if path.is_dir():
        raise InputError("cannot write (a folder of that name exists)", source=source,
                         field=field)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("ab"):
            pass
    except OSError as exc:
        raise InputError(f"cannot write ({exc.strerror or exc})", source=source,
                         field=field) from None
    if not existed:
        path.unlink()


def _keep_partial(trajectory: Trajectory | None, args: argparse.Namespace, progress: bool,
                  steps_were: str) -> str:
    """Save and animate the steps of a run cut short; returns where they went ('' if not)."""
    if trajectory is None:
        return ""
    kept = []
    if args.out:
        path = _save(trajectory, args.out)
        kept.append(str(path))
        print(f"{PROG}: saved the {_count(trajectory.n_steps, 'step')} {steps_were} to {path}",
              file=sys.stderr)
    if args.animate:  # a picture of the run so far
        written = _animate(trajectory, args, progress)
        kept.append(str(written))
        print(f"{PROG}: animated the {_count(trajectory.n_steps, 'step')} {steps_were} in "
              f"{written}", file=sys.stderr)
    return " and ".join(kept)


def _animate(trajectory: Trajectory, args: argparse.Namespace, progress: bool) -> Path:
    from .animation import animate

    return animate(trajectory, args.animate, fps=args.fps, progress=progress)


def _bench(args: argparse.Namespace) -> int:
    from .lab.bench.suite import Suite
    from .lab.bench.sweep import RESULTS_FILE, run_sweep

    dask = None
    if args.dask is not None or args.scheduler is not None:
        from .lab.bench.dask_sweep import DaskCluster, require_distributed

        dask = DaskCluster(workers=args.dask, scheduler=args.scheduler)
        require_distributed(dask.option)  # before the suite is read
    suite = Suite.named(args.suite)
    out = Path(args.out) if args.out else Path("bench-results") / suite.name
    try:
        summary = run_sweep(suite, out, jobs=args.jobs, progress=args.progress, dask=dask)
    except KeyboardInterrupt:  # the rows written stay; the points cut short run on resume
        print(f"{PROG}: interrupted; the finished rows are in {out / RESULTS_FILE}, and the "
              "same command runs the rest", file=sys.stderr)
        return INTERRUPTED
    print(f"suite {suite.name}: {summary.ran} grid points run, {summary.skipped_done} already "
          f"done, {len(summary.skipped_unavailable)} skipped (not installed), "
          f"{summary.failed} failed or errored")
    print(f"results: {summary.results}")
    print(f"report:  {PROG} report {summary.results}")
    return 0


def _report(args: argparse.Namespace) -> int:
    from .lab.bench.report import write_report

    path = write_report(args.results, args.root, headline=args.headline)
    print(f"wrote {path}")
    return 0


def _robustness(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    from .lab.robustness.report import write_robustness_report

    for name in ("scenes", "fuzz", "steps"):
        if getattr(args, name) < 0:
            raise InputError(f"must be a non-negative integer, got {getattr(args, name)}",
                             field=f"--{name}")
    words = sys.argv[1:] if argv is None else list(argv)
    try:
        path = write_robustness_report(
            Path(args.out), args.scenes, args.fuzz, args.seed, steps=args.steps,
            command=" ".join([PROG, *words]),
            say=lambda text: print(text, file=sys.stderr))
    except KeyboardInterrupt:  # the report is written whole or not at all
        print(f"{PROG}: interrupted; {args.out} not written", file=sys.stderr)
        return INTERRUPTED
    print(f"wrote {path}")
    return 0


def _export_qps(args: argparse.Namespace) -> int:
    from .lab.bench.suite import Suite
    from .lab.qp_export import export_qps

    if args.steps is not None and args.steps < 1:
        raise InputError(f"must be a positive integer, got {args.steps}", field="--steps")
    summary = export_qps(Suite.named(args.suite), Path(args.out), scene=args.scene,
                         steps=args.steps, every=args.every, ours=args.ours,
                         say=lambda text: print(text, file=sys.stderr))
    print(f"wrote {summary.problems} QPs of {summary.runs} runs to {summary.out} "
          f"({summary.manifest.name}; test set {summary.test_set.name})")
    print(f"run:  cd {summary.out} && qpbenchmark {summary.test_set.name} list_problems")
    return 0


def _save(trajectory: Trajectory, out: str) -> Path:
    """Save to ``--out``; a path that cannot be written is an :class:`InputError`."""
    try:
        return trajectory.save(out)
    except OSError as exc:
        raise InputError(f"cannot write ({exc.strerror})", source=out, field="--out") from None


if __name__ == "__main__":  # ``python -m wuerfel_cvx`` also takes a Ctrl-C during start-up
    from .__main__ import main as entry

    sys.exit(entry())
