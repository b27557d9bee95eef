"""The report regeneration driver: budgets end a command with Ctrl-C, jobs run in order."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wuerfel_cvx.lab import regenerate
from wuerfel_cvx.lab.bench.suite import suite_names
from wuerfel_cvx.lab.regenerate import JOBS, Job, run_job

pytestmark = pytest.mark.subprocess


def test_a_finished_job_runs_its_commands_in_order(tmp_path: Path) -> None:
    log = tmp_path / "log"
    write = "import sys; open(sys.argv[1], 'a').write(sys.argv[2])"
    job = Job("two", ((sys.executable, "-c", write, str(log), "a"),
                      (sys.executable, "-c", write, str(log), "b")), budget_minutes=1.0)
    assert run_job(job)
    assert log.read_text() == "ab"


def test_a_missing_command_is_one_line_and_the_job_fails(capsys: pytest.CaptureFixture[str],
                                                         tmp_path: Path) -> None:
    log = tmp_path / "log"
    job = Job("lost", (("no-such-command-here",), (sys.executable, "-c",
                                                   f"open({str(log)!r}, 'w')")), 1.0)
    assert not run_job(job)
    assert "'no-such-command-here' not found" in capsys.readouterr().err
    assert not log.exists()  # the job stops at its first missing command


def test_a_spent_budget_interrupts_the_command_and_skips_the_rest(tmp_path: Path) -> None:
    """The command gets Ctrl-C at the deadline, and the report step after it does not run.

    (A Python child exits 130 on Ctrl-C here, as our commands do.)
    """
    log = tmp_path / "log"
    sleeper = ("import signal, sys, time\n"
               "signal.signal(signal.SIGINT, lambda *_: sys.exit(130))\n"
               "time.sleep(60)\n")
    job = Job("slow", ((sys.executable, "-c", sleeper),
                       (sys.executable, "-c", f"open({str(log)!r}, 'w')")),
              budget_minutes=0.02)
    started = time.monotonic()
    assert not run_job(job)
    assert time.monotonic() - started < 30.0  # stopped at the budget, not after 60 s
    assert not log.exists()


def test_the_jobs_name_existing_suites() -> None:
    names = set(suite_names())
    for job in JOBS:
        if job.commands[0][:2] == ("wuerfel-cvx", "bench"):
            assert job.name in names
    assert regenerate.main(["--list"]) == 0


def test_ctrl_c_stops_the_driver_with_130_and_no_traceback(tmp_path: Path) -> None:
    """A Ctrl-C at the terminal reaches the driver and its command (one process group)."""
    started = tmp_path / "started"
    child = ("import signal, sys, time\n"
             "signal.signal(signal.SIGINT, lambda *_: sys.exit(130))\n"
             f"open({str(started)!r}, 'w')\n"
             "time.sleep(60)\n")
    driver = ("import sys\n"
              "from wuerfel_cvx.lab import regenerate\n"
              f"regenerate.JOBS = (regenerate.Job('slow', (({sys.executable!r}, '-c', "
              f"{child!r}),), budget_minutes=5.0),)\n"
              "sys.exit(regenerate.main([]))\n")
    process = subprocess.Popen([sys.executable, "-c", driver], stderr=subprocess.PIPE,
                               text=True, start_new_session=True)
    deadline = time.monotonic() + 60.0
    while not started.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert started.exists(), "the job's command did not start"
    os.killpg(process.pid, signal.SIGINT)  # as the terminal does
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert "Traceback" not in err, err
    assert err.strip().splitlines()[-1] == (
        "regenerate: interrupted; finished rows are kept, the same command resumes")
