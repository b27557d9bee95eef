"""The ``wuerfel-cvx`` command line.

``wuerfel-cvx simulate SCENE ...`` runs a simulation and prints a summary;
``wuerfel-cvx scenes`` lists the named scenes; ``wuerfel-cvx solvers`` lists the
installed solvers.  Bad input ends with one line on standard error and exit status 2;
a failed step ends with status 1 after saving the trajectory computed so far.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .errors import InputError, StepFailure
from .formulations import FORMULATIONS
from .library import ENTRIES
from .simulate import simulate
from .solvers import SOLVERS, TOLERANCE_PRESETS, available_solvers
from .trajectory import Trajectory

PROG = "wuerfel-cvx"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``wuerfel-cvx`` command."""
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser("simulate", help="simulate a scene and print a summary")
    run.add_argument("scene", help="a named scene (see 'wuerfel-cvx scenes') or a .toml path")
    run.add_argument("--dt", type=float, default=0.01, help="time step in s (default 0.01)")
    run.add_argument("--steps", type=int, default=200, help="number of steps (default 200)")
    run.add_argument("--solver", default="CLARABEL",
                     help=f"solver name, case-insensitive (known: {', '.join(SOLVERS)})")
    run.add_argument("--formulation", default="velocity",
                     help=f"formulation ({', '.join(FORMULATIONS)}; default velocity)")
    run.add_argument("--tol", default="default",
                     help=f"tolerance preset ({', '.join(TOLERANCE_PRESETS)}) or a number")
    run.add_argument("--table-mass", type=float, default=None,
                     help="seed variant: table corners as variables of this mass (kg)")
    run.add_argument("--out", default=None,
                     help="write the trajectory (.npz) and metrics (.metrics.csv) here")
    run.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar (default: on when standard error is a terminal)")

    commands.add_parser("scenes", help="list the named scenes")
    commands.add_parser("solvers", help="list the installed solvers")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        if args.command == "scenes":
            width = max(len(entry.pattern) for entry in ENTRIES)
            for entry in ENTRIES:
                print(f"{entry.pattern:<{width}}  {entry.description}")
            return 0
        if args.command == "solvers":
            for name in available_solvers():
                print(f"{name:<9} {SOLVERS[name].kind}")
            return 0
        return _simulate(args)
    except InputError as exc:
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2


def _simulate(args: argparse.Namespace) -> int:
    progress = sys.stderr.isatty() if args.progress is None else args.progress
    try:
        trajectory = simulate(args.scene, dt=args.dt, steps=args.steps, solver=args.solver,
                              formulation=args.formulation, tol=args.tol,
                              table_mass=args.table_mass, progress=progress)
    except StepFailure as failure:
        print(f"{PROG}: {failure}", file=sys.stderr)
        if args.out and failure.trajectory is not None:
            path = _save(failure.trajectory, args.out)
            print(f"{PROG}: saved the {failure.trajectory.n_steps} steps before it to {path}",
                  file=sys.stderr)
        return 1
    print(trajectory.summary())
    if args.out:
        path = _save(trajectory, args.out)
        print(f"saved {path} and {trajectory.metrics_path(path)}")
    return 0


def _save(trajectory: Trajectory, out: str) -> Path:
    try:
        return trajectory.save(out)
    except OSError as exc:
        raise InputError(f"cannot write ({exc.strerror})", source=out, field="--out") from None


if __name__ == "__main__":
    sys.exit(main())
