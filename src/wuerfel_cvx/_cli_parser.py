"""The options of the ``wuerfel-cvx`` command line (:mod:`wuerfel_cvx.cli` runs them).

Help texts are plain text: what they list (installed solvers, bundled suites) comes from
the same place as the checks and errors.
"""

from __future__ import annotations

import argparse
import re
from typing import TYPE_CHECKING

from .__main__ import PROG
from .formulations import DEFAULT_FORMULATION, FORMULATIONS, FRICTION_MODELS
from .solve.registry import TOLERANCE_PRESETS

DEFAULT_SOLVER = "CLARABEL"
"""The solver of ``simulate`` when ``--solver`` is not given (as :func:`simulate`'s)."""


def build_parser(description: str) -> argparse.ArgumentParser:
    """The argument parser of the ``wuerfel-cvx`` command (``description`` made plain)."""
    parser = argparse.ArgumentParser(prog=PROG, description=plain(description))
    parser.add_argument("--version", action="version", version=f"{PROG} {package_version()}")
    commands = parser.add_subparsers(dest="command", required=True)
    _add_simulate_parser(commands)
    _add_bench_parser(commands)
    report = commands.add_parser("report", help="write reports/<suite>/README.md from results")
    report.add_argument("results", help="a results CSV written by 'wuerfel-cvx bench'")
    report.add_argument("--root", default="reports",
                        help="reports directory (default reports)")
    report.add_argument("--headline", default=None,
                        help="scene of the large speed/accuracy plot (default: the scene "
                             "with the most points)")
    _add_robustness_parser(commands)
    _add_export_parser(commands)
    commands.add_parser("scenes", help="list the named scenes")
    commands.add_parser("solvers", help="list the installed solvers")
    return parser


def plain(text: str) -> str:
    """``text`` without reStructuredText markup: roles (``:func:`x```) and literals."""
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", text)
    return text.replace("``", "")


if TYPE_CHECKING:
    Commands = argparse._SubParsersAction[argparse.ArgumentParser]


def _add_simulate_parser(commands: Commands) -> None:
    """The ``simulate`` subcommand's arguments."""
    run = commands.add_parser("simulate", help="simulate a scene and print a summary")
    run.add_argument("scene", help="a named scene (see 'wuerfel-cvx scenes') or a .toml path")
    run.add_argument("--dt", type=float, default=0.01, help="time step in s (default 0.01)")
    run.add_argument("--steps", type=int, default=200, help="number of steps (default 200)")
    run.add_argument("--solver", default=DEFAULT_SOLVER,
                     help=f"solver, case-insensitive (those installed: 'wuerfel-cvx solvers'; "
                          f"default {DEFAULT_SOLVER})")
    run.add_argument("--formulation", default=DEFAULT_FORMULATION,
                     help=f"formulation ({', '.join(FORMULATIONS)}; default "
                          f"{DEFAULT_FORMULATION})")
    run.add_argument("--friction-model", default=None,
                     help=f"friction model for scenes with friction ({', '.join(FRICTION_MODELS)}"
                          f"; default {FRICTION_MODELS[0]}); a scene without friction says so")
    run.add_argument("--tol", default="default",
                     help=f"tolerance preset ({', '.join(TOLERANCE_PRESETS)}) or a number")
    run.add_argument("--solve-path", default="native", choices=("native", "compiled",
                                                                "declared"),
                     help="how the QPs reach the solver: its own API (native, the default), "
                          "a cvxpy problem compiled per structure, or one declared per step")
    run.add_argument("--polish", action=argparse.BooleanOptionalAction, default=True,
                     help="polish every answer on its active set (default on; --no-polish: "
                          "the answers as the solver gave them)")
    run.add_argument("--table-mass", type=float, default=None,
                     help="the seed's heavy table: table corners as variables of this mass "
                          "(kg), held still by equalities (a larger QP; the tables do not "
                          "move)")
    run.add_argument("--fallback", action="append", default=[], metavar="NAME",
                     help="solver to retry a failed step with (repeatable; the metrics "
                          "record it in 'solver' and the failed status in 'primary_status')")
    run.add_argument("--sleep", action="store_true",
                     help="let islands at rest sleep (left out of the QP until touched)")
    run.add_argument("--islands", action="store_true",
                     help="solve each island (squares joined by contacts) as its own QP")
    run.add_argument("--out", default=None,
                     help="write the trajectory (.npz) and metrics (.metrics.csv) here; a "
                          "folder (ending in / or existing) gets <scene>.npz inside")
    run.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                     help="progress bar (default: on when standard error is a terminal)")
    run.add_argument("--animate", default=None, metavar="PATH",
                     help="write an animation here (.gif; .mp4 needs ffmpeg)")
    run.add_argument("--fps", type=float, default=25.0,
                     help="animation frames per simulated second (default 25)")


def _add_bench_parser(commands: Commands) -> None:
    """The ``bench`` subcommand's arguments."""
    from .lab.bench.suite import suite_names

    bench = commands.add_parser("bench", help="run a benchmark suite (rows append; resumes)")
    bench.add_argument("--suite", required=True,
                       help=f"suite name ({', '.join(suite_names())}) or a .toml path")
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


def _add_robustness_parser(commands: Commands) -> None:
    """The ``robustness`` subcommand's arguments."""
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


ROBUSTNESS_OUT = "bench-results/robustness.md"
"""Where ``wuerfel-cvx robustness`` writes by default: beside the sweeps' results, not over
the committed report."""
ROBUSTNESS_REPORT = "reports/robustness.md"
"""The repository's robustness report, written with ``--report``."""


def _add_export_parser(commands: Commands) -> None:
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
