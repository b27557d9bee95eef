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
import sys
from collections.abc import Sequence
from pathlib import Path

from ._entry import INTERRUPTED, PROG
from .errors import InputError, Interrupted, StepFailure
from .formulations import FORMULATIONS, FRICTION_MODELS
from .library import ENTRIES
from .simulate import simulate
from .sleep import SleepSettings
from .solvers import SOLVERS, TOLERANCE_PRESETS, available_solvers
from .trajectory import Trajectory


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``wuerfel-cvx`` command."""
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"{PROG} {package_version()}")
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("simulate", help="simulate a scene and print a summary")
    run.add_argument("scene", help="a named scene (see 'wuerfel-cvx scenes') or a .toml path")
    run.add_argument("--dt", type=float, default=0.01, help="time step in s (default 0.01)")
    run.add_argument("--steps", type=int, default=200, help="number of steps (default 200)")
    run.add_argument("--solver", default="CLARABEL",
                     help=f"solver name, case-insensitive (known: {', '.join(SOLVERS)})")
    run.add_argument("--formulation", default="velocity",
                     help=f"formulation ({', '.join(FORMULATIONS)}; default velocity)")
    run.add_argument("--friction-model", default=FRICTION_MODELS[0],
                     help=f"friction model for scenes with friction ({', '.join(FRICTION_MODELS)}"
                          f"; default {FRICTION_MODELS[0]})")
    run.add_argument("--tol", default="default",
                     help=f"tolerance preset ({', '.join(TOLERANCE_PRESETS)}) or a number")
    run.add_argument("--table-mass", type=float, default=None,
                     help="seed variant: table corners as variables of this mass (kg)")
    run.add_argument("--fallback", action="append", default=[], metavar="NAME",
                     help="solver to retry a failed step with (repeatable; the metrics "
                          "record it in 'solver' and the failed status in 'primary_status')")
    run.add_argument("--sleep", action="store_true",
                     help="let islands at rest sleep (left out of the QP until touched)")
    run.add_argument("--islands", action="store_true",
                     help="solve each island (squares joined by contacts) as its own QP")
    run.add_argument("--out", default=None,
                     help="write the trajectory (.npz) and metrics (.metrics.csv) here")
    run.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar (default: on when standard error is a terminal)")
    run.add_argument("--animate", default=None, metavar="PATH",
                     help="write an animation here (.gif; .mp4 needs ffmpeg)")
    run.add_argument("--fps", type=float, default=25.0,
                     help="animation frames per simulated second (default 25)")

    bench = commands.add_parser("bench", help="run a benchmark suite (rows append; resumes)")
    bench.add_argument("--suite", required=True,
                       help="suite name (benchmarks/<NAME>.toml: smoke, standard, hard, "
                            "scaling) or a .toml path")
    bench.add_argument("--out", default=None,
                       help="results directory (default bench-results/<suite>)")
    bench.add_argument("--jobs", type=int, default=1,
                       help="worker processes (default 1; timings are cleanest with 1)")
    bench.add_argument("--dask", type=int, default=None, metavar="N",
                       help="run on a dask.distributed LocalCluster of N worker processes "
                            "(the 'dask' extra)")
    bench.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run on the Dask cluster of the scheduler at ADDRESS")
    bench.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                       help="progress bar with ETA (default: on when stderr is a terminal)")

    report = commands.add_parser("report", help="write reports/<suite>/README.md from results")
    report.add_argument("results", help="a results CSV written by 'wuerfel-cvx bench'")
    report.add_argument("--root", default="reports",
                        help="reports directory (default reports)")
    report.add_argument("--headline", default=None,
                        help="scene of the large speed/accuracy plot (default: the scene "
                             "with the most points)")

    robust = commands.add_parser(
        "robustness", help="generated scenes, fuzzed scene files and solver faults "
                           f"-> {ROBUSTNESS_OUT} (--report: {ROBUSTNESS_REPORT})")
    robust.add_argument("--scenes", type=int, default=200,
                        help="random valid scenes to simulate and check (default 200)")
    robust.add_argument("--fuzz", type=int, default=2000,
                        help="mutated scene files to load and step (default 2000)")
    robust.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    robust.add_argument("--steps", type=int, default=200,
                        help="steps per generated scene (default 200)")
    where = robust.add_mutually_exclusive_group()
    where.add_argument("--out", default=ROBUSTNESS_OUT,
                       help=f"report file (default {ROBUSTNESS_OUT})")
    where.add_argument("--report", action="store_const", dest="out",
                       const=ROBUSTNESS_REPORT,
                       help=f"write the repository's report, {ROBUSTNESS_REPORT}")

    _add_export_parser(commands)
    commands.add_parser("scenes", help="list the named scenes")
    commands.add_parser("solvers", help="list the installed solvers")
    return parser


ROBUSTNESS_OUT = "bench-results/robustness.md"
"""Where ``wuerfel-cvx robustness`` writes by default: beside the sweeps' results, not over
the committed report."""
ROBUSTNESS_REPORT = "reports/robustness.md"
"""The repository's robustness report, written with ``--report``."""


def _add_export_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The ``export-qps`` subcommand's arguments."""
    export = commands.add_parser(
        "export-qps", help="write a suite's step QPs as a qpbenchmark test set")
    export.add_argument("--suite", required=True, help="suite name or a .toml path")
    export.add_argument("--out", required=True, help="folder of the test set")
    export.add_argument("--scene", default=None, help="only this scene's runs")
    export.add_argument("--steps", type=int, default=None,
                        help="at most this many steps per run (default: the suite's)")
    export.add_argument("--every", type=int, default=1,
                        help="keep the QP of step 1 and of every N-th step after (default 1)")
    export.add_argument("--ours", action="store_true",
                        help="also solve each QP with our solvers and presets (ours.csv)")


def package_version() -> str:
    """The installed version of the package (from its distribution's metadata)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("wuerfel_cvx")
    except PackageNotFoundError:  # run from a source tree that was never installed
        from . import __version__

        return f"{__version__} (not installed)"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    try:
        args = build_parser().parse_args(argv)
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
    _check_outputs(args)  # a bad --out, --animate or --fps is reported before the run
    try:
        trajectory = simulate(args.scene, dt=args.dt, steps=args.steps, solver=args.solver,
                              formulation=args.formulation, tol=args.tol,
                              table_mass=args.table_mass, progress=progress,
                              sleep=SleepSettings() if args.sleep else None,
                              islands=args.islands, fallback=args.fallback,
                              friction_model=args.friction_model)
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
    rescued = trajectory.metrics["status"] != trajectory.metrics["primary_status"]
    if rescued.any():
        print(f"fallback             {int(rescued.sum())} steps solved by "
              f"{', '.join(sorted(set(trajectory.metrics['solver'][rescued])))} after "
              f"{trajectory.info['solver']} failed")
    if args.out:
        path = _save(trajectory, args.out)
        print(f"saved {path} and {trajectory.metrics_path(path)}")
    if args.animate:
        print(f"wrote {_animate(trajectory, args, progress)}")
    return 0


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
    from .bench.suite import Suite
    from .bench.sweep import RESULTS_FILE, run_sweep

    dask = None
    if args.dask is not None or args.scheduler is not None:
        from .bench.dask_sweep import DaskCluster, require_distributed

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
    from .bench.report import write_report

    path = write_report(args.results, args.root, headline=args.headline)
    print(f"wrote {path}")
    return 0


def _robustness(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    from .robustness.report import write_robustness_report

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
    from .bench.suite import Suite
    from .qp_export import export_qps

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
    from ._entry import main as entry

    sys.exit(entry())
