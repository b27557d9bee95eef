"""Regenerate the study's reports on today's physics: ``python -m wuerfel_cvx.lab.regenerate``.

One job per folder of ``reports/``, run in order, each a list of commands with a time
budget.  A benchmark suite's sweep writes its rows to ``bench-results/<suite>`` (resumable:
a second run carries on where the first stopped) and records the physics it ran
(``provenance.json``); once every point has a row, ``wuerfel-cvx report`` writes
``reports/<suite>`` with the physics fingerprint in its header.  A sweep still running when
its budget is spent gets a Ctrl-C, which keeps every finished row and stops without writing
the report: run the command again to resume.  ``--only`` picks jobs, ``--budget-scale``
stretches every budget, ``--list`` shows the jobs and their commands.
"""

from __future__ import annotations

import argparse
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from .bench.report import report_fingerprint
from .robustness.determinism import physics_fingerprint

INTERRUPTED = 130
"""Exit status of a command stopped by Ctrl-C (the budget's end)."""


@dataclass(frozen=True)
class Job:
    """One report folder: the commands that regenerate it, run in order, and their budget."""

    name: str
    commands: tuple[tuple[str, ...], ...]
    budget_minutes: float
    """Wall-time budget (min) on the 2-core machine of the README, for all its commands."""
    needs: str = ""
    """A console command the job needs (an extra's), or '' for the core install."""
    report: str = ""
    """The report file the job writes, relative to the repository ('' : its suite's
    ``reports/<name>/README.md``)."""

    @property
    def report_path(self) -> str:
        """The report file the job writes (its header states the physics fingerprint)."""
        return self.report or f"reports/{self.name}/README.md"


def suite_job(suite: str, budget_minutes: float, jobs: int = 1,
              headline: str | None = None) -> Job:
    """A benchmark suite's job: its sweep (resumable) then its report.

    ``headline``: the scene of the report's large speed-against-accuracy plot (default: the
    scene with the most points).
    """
    out = f"bench-results/{suite}"
    report = ("wuerfel-cvx", "report", f"{out}/results.csv", "--root", "reports",
              *(("--headline", headline) if headline else ()))
    return Job(suite, (("wuerfel-cvx", "bench", "--suite", suite, "--out", out,
                        "--jobs", str(jobs), "--no-progress"), report), budget_minutes)


JOBS = (
    suite_job("perf", 15),  # one process: its times are the report's point
    suite_job("scaling", 20),
    suite_job("standard", 30, jobs=2, headline="stack-10"),  # the README's picture
    suite_job("hard", 20, jobs=2),
    suite_job("polish", 20, jobs=2),
    suite_job("islands", 10),
    suite_job("friction", 600, jobs=2),
    Job("hard-targets", (
        ("wuerfel-cvx", "bench", "--suite", "hard-targets", "--out", "bench-results/hard-targets",
         "--jobs", "2", "--no-progress"),
        ("cp", "bench-results/hard-targets/results.csv", "reports/hard/targets-after.csv"),
        ("cp", "bench-results/hard-targets/provenance.json",
         "reports/hard/targets-after-provenance.json"),
        (sys.executable, "-m", "wuerfel_cvx.lab.bench.targets", "sweep", "--scenes", "800",
         "--seed", "0", "--out", "reports/hard/generated-energy-after.csv"),
        (sys.executable, "-m", "wuerfel_cvx.lab.bench.targets", "report",
         "--before", "reports/hard/targets-before.csv",
         "--before-generated", "reports/hard/generated-energy-before.csv",
         "--after", "reports/hard/targets-after.csv",
         "--after-generated", "reports/hard/generated-energy-after.csv",
         "--after-provenance", "reports/hard/targets-after-provenance.json",
         "--out", "reports/hard/targets.md")), 15, report="reports/hard/targets.md"),
    Job("friction-targets", (
        (sys.executable, "-m", "wuerfel_cvx.lab.bench.friction_targets", "measure",
         "--out", "reports/friction"),
        (sys.executable, "-m", "wuerfel_cvx.lab.bench.friction_targets", "report",
         "reports/friction/targets.csv", "--out", "reports/friction/targets.md")), 120,
        report="reports/friction/targets.md"),
    Job("robustness", (("wuerfel-cvx", "robustness", "--scenes", "200", "--fuzz", "2000",
                        "--report"),), 30, report="reports/robustness.md"),
    Job("gradients", ((sys.executable, "-m", "wuerfel_cvx.lab.bench.report_gradients",
                       "--out", "reports/gradients", "--repeats", "3"),), 20),
    Job("qpbenchmark", (
        ("wuerfel-cvx", "export-qps", "--suite", "qpbenchmark", "--out", "reports/qpbenchmark",
         "--every", "10", "--ours"),
        ("sh", "-c", "cd reports/qpbenchmark && rm -f wuerfel_step_qps.csv && qpbenchmark "
         "wuerfel_step_qps.py --results-path wuerfel_step_qps.csv run --author wuerfel_cvx"),
        (sys.executable, "-m", "wuerfel_cvx.lab.qp_export.compare", "reports/qpbenchmark",
         "--out", "reports/qpbenchmark")), 60, needs="qpbenchmark",
        report="reports/qpbenchmark/comparison.md"),
)
"""Every regenerated report, cheapest first (the Coulomb card house makes ``friction`` the
longest by far)."""


HEADLINE_REPORTS = ("standard", "perf", "scaling")
"""The jobs whose reports the README's headline picture and speed tables come from: they
must be on today's physics (``tests/test_readme_reports.py``)."""


def report_table(root: Path, current: str) -> str:
    """Markdown: every job's report, its physics fingerprint and whether it is ``current``."""
    lines = ["| report | physics fingerprint | on today's physics |", "|---|---|---|"]
    for job in JOBS:
        path = root / job.report_path
        found = report_fingerprint(path.read_text(encoding="utf-8")) if path.exists() else None
        state = ("yes" if found == current else
                 "no: not regenerated since the physics changed" if found else
                 "no: made before reports stated their physics")
        lines.append(f"| [`{job.name}`]({job.report_path}) | "
                     f"{f'`{found}`' if found else '–'} | {state} |")
    return "\n".join(lines)


def run_job(job: Job, scale: float = 1.0) -> bool:
    """Run ``job``'s commands within its budget; whether they all finished."""
    if job.needs and shutil.which(job.needs) is None:
        print(f"{job.name}: skipped ({job.needs} is not installed)", file=sys.stderr)
        return False
    deadline = time.monotonic() + 60.0 * job.budget_minutes * scale
    for command in job.commands:
        print(f"{job.name}: {' '.join(command)}", file=sys.stderr, flush=True)
        try:
            status = _run_until(command, deadline)
        except FileNotFoundError:
            print(f"{job.name}: command '{command[0]}' not found (is the package's "
                  "environment active?)", file=sys.stderr)
            return False
        if status == INTERRUPTED:
            print(f"{job.name}: budget spent; finished rows are kept, run again to resume",
                  file=sys.stderr)
            return False
        if status != 0:
            print(f"{job.name}: '{' '.join(command)}' exited with {status}", file=sys.stderr)
            return False
    return True


def _run_until(command: Sequence[str], deadline: float) -> int:
    """Run ``command``; at ``deadline`` (monotonic s) send it Ctrl-C and wait for it."""
    process = subprocess.Popen(command)
    try:
        return process.wait(timeout=max(0.0, deadline - time.monotonic()))
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGINT)
        return process.wait()
    except KeyboardInterrupt:  # the terminal's Ctrl-C reached the command as well
        process.wait()  # which keeps its finished rows and stops
        raise


def main(argv: Sequence[str] | None = None) -> int:
    """Run the jobs asked for: 0 when every one finished, 1 otherwise (see stderr).

    130 on Ctrl-C (the running command gets it too, and keeps its finished rows).
    """
    parser = argparse.ArgumentParser(prog="python -m wuerfel_cvx.lab.regenerate",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=[job.name for job in JOBS],
                        help="these jobs only (default: all, in order)")
    parser.add_argument("--budget-scale", type=float, default=1.0,
                        help="multiply every job's budget (default 1)")
    parser.add_argument("--list", action="store_true", help="list the jobs and exit")
    parser.add_argument("--table", action="store_true",
                        help="print the README's table of the reports' physics and exit")
    args = parser.parse_args(argv)
    if args.table:
        print(report_table(Path.cwd(), physics_fingerprint()))
        return 0
    chosen = [job for job in JOBS if args.only is None or job.name in args.only]
    if args.list:
        for job in chosen:
            print(f"{job.name} ({job.budget_minutes:g} min):")
            for command in job.commands:
                print("    " + " ".join(command))
        return 0
    if args.budget_scale <= 0:
        parser.error("--budget-scale must be positive")
    try:
        finished = [run_job(job, args.budget_scale) for job in chosen]
    except KeyboardInterrupt:
        print("regenerate: interrupted; finished rows are kept, the same command resumes",
              file=sys.stderr)
        return INTERRUPTED
    return 0 if all(finished) else 1


if __name__ == "__main__":  # pragma: no cover - the command itself
    raise SystemExit(main())
