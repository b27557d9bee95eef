"""Ctrl-C in real processes: ``simulate``, ``bench`` (one process, a pool, Dask), ``robustness``.

Most tests start ``python -m wuerfel_cvx`` (what the ``wuerfel-cvx`` script runs) in a
session of its own and sends SIGINT to its whole process group, as a terminal does on
Ctrl-C.  It then checks what a user sees: exit status 130, one line and no traceback on
standard error, no process of the command left running, every finished row kept, and the
point cut short run again, not written, on resume.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from wuerfel_cvx.errors import Interrupted, WuerfelError
from wuerfel_cvx.lab.bench import runner, schema
from wuerfel_cvx.lab.bench.suite import Suite
from wuerfel_cvx.lab.bench.sweep import RESULTS_FILE
from wuerfel_cvx.trajectory import Trajectory

LINUX = pytest.mark.skipif(not Path("/proc/self/stat").exists(),
                           reason="reads the process table from /proc (Linux)")

TIMEOUT = 180.0
"""Seconds a command may take to reach the point where the test presses Ctrl-C."""
STOP_WITHIN = 30.0
"""Seconds a command may take to exit after Ctrl-C (imports and a cluster's close)."""


@pytest.fixture(scope="module", autouse=True)
def compiled_kernels() -> None:
    """The step path's kernels compiled into numba's cache before any command is timed.

    In a fresh environment the first process to use them compiles them (9 to 16 s); a
    Ctrl-C pressed in that window is answered after the compilation, which the 30 s bound
    is not about.  Each formulation and the Coulomb fixed point compile their kernels here,
    and one generated scene of the property sweep the contact search's other
    specialisations (two more, about 3 s: once compiled in the robustness command's first
    second, its Ctrl-C was answered after 30 s on a loaded CI run).
    """
    code = ("from wuerfel_cvx import simulate\n"
            "from wuerfel_cvx.lab.robustness.properties import run_property_sweep\n"
            "for formulation in ('velocity', 'rigid', 'seed'):\n"
            "    simulate('stack-3', steps=2, formulation=formulation)\n"
            "simulate('card-house', dt=1/60, steps=1, friction_model='coulomb')\n"
            "run_property_sweep(1, 0, steps=2)\n")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=600,
                   capture_output=True)


@dataclass
class Command:
    """``python -m wuerfel_cvx ARGS`` in a process group of its own, its stderr collected."""

    args: list[str]
    cwd: Path
    process: subprocess.Popen[bytes] = field(init=False)
    _stderr: list[bytes] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.process = subprocess.Popen([sys.executable, "-m", "wuerfel_cvx", *self.args],
                                        cwd=self.cwd, stdout=subprocess.PIPE,
                                        stderr=subprocess.PIPE, start_new_session=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stderr is not None
        while chunk := os.read(self.process.stderr.fileno(), 4096):
            self._stderr.append(chunk)

    @property
    def stderr(self) -> str:
        """Standard error so far."""
        return b"".join(self._stderr).decode("utf-8", "replace")

    def wait_until(self, ready: Callable[[], bool], what: str) -> None:
        """Wait until ``ready()``; fail naming ``what`` if the command ends or times out."""
        deadline = time.monotonic() + TIMEOUT
        while not ready():
            if self.process.poll() is not None:
                pytest.fail(f"the command ended before {what}:\n{self.stderr}")
            if time.monotonic() > deadline:
                self.kill()
                pytest.fail(f"no {what} within {TIMEOUT:g} s:\n{self.stderr}")
            time.sleep(0.02)

    def press_ctrl_c(self, times: int = 1) -> None:
        """SIGINT to every process of the command, as a terminal sends Ctrl-C."""
        for _ in range(times):
            os.killpg(self.process.pid, signal.SIGINT)
            time.sleep(0.1)

    def finish(self) -> tuple[int, str, str]:
        """Exit status, stdout and stderr, once it has exited (within :data:`STOP_WITHIN`)."""
        try:
            self.process.wait(timeout=STOP_WITHIN)  # (its stdout is short: no pipe fills)
        except subprocess.TimeoutExpired:
            self.kill()
            pytest.fail(f"still running {STOP_WITHIN:g} s after Ctrl-C:\n{self.stderr}")
        self._reader.join(timeout=10)
        assert self.process.stdout is not None and self.process.stderr is not None
        with self.process.stdout, self.process.stderr:
            return self.process.returncode, self.process.stdout.read().decode(), self.stderr

    def left_running(self) -> list[str]:
        """Processes of the command's group still alive (zombies left to init excluded)."""
        time.sleep(0.5)  # workers told to stop are reaped by then
        alive = []
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
            except OSError:  # ended meanwhile
                continue
            state, group = fields[0], int(fields[2])
            if group == self.process.pid and state != "Z":
                alive.append(stat.parent.name)
        return alive

    def kill(self) -> None:
        """End the whole group (a failed test leaves nothing behind)."""
        try:
            os.killpg(self.process.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.process.wait()


def assert_stopped_cleanly(command: Command) -> tuple[str, str]:
    """Exit status 130, no traceback, no process left; stdout and stderr."""
    status, out, err = command.finish()
    assert status == 130, (status, out, err)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert command.left_running() == [], "processes of the command left running"
    return out, err


def relay_started(command: Command) -> Callable[[], bool]:
    """True once the command runs more than one thread: its Ctrl-C relay has started."""
    tasks = Path(f"/proc/{command.process.pid}/task")
    return lambda: tasks.is_dir() and len(list(tasks.iterdir())) > 1


# -------------------------------------------------------------------------- in-process
@pytest.mark.unit
def test_ctrl_c_is_not_an_error_that_catch_all_handlers_take() -> None:
    stop = Interrupted(3)
    assert isinstance(stop, KeyboardInterrupt)
    assert not isinstance(stop, Exception) and not isinstance(stop, WuerfelError)


@pytest.mark.unit
def test_a_grid_point_cut_short_by_ctrl_c_becomes_no_row(monkeypatch: pytest.MonkeyPatch,
                                                         tmp_path: Path) -> None:
    def interrupted(*args: object, **kwargs: object) -> Trajectory:
        raise Interrupted(13)

    monkeypatch.setattr(runner, "simulate", interrupted)
    point = Suite.from_dict({"name": "s", "grid": [{"scenes": ["tilted-drop"],
                                                    "duration": 0.05}]}).points[0]
    with pytest.raises(Interrupted):
        runner.run_point(point, None, tmp_path / "series")
    assert not (tmp_path / "series").exists()


@pytest.mark.subprocess
def test_the_package_imports_cvxpy_only_when_a_name_needs_it() -> None:
    code = ("import sys, wuerfel_cvx, wuerfel_cvx.__main__\n"
            "assert 'cvxpy' not in sys.modules and 'numpy' not in sys.modules\n"
            "import wuerfel_cvx.lab.bench.runner  # imports the module wuerfel_cvx.simulate\n"
            "from wuerfel_cvx import Scene, simulate\n"
            "assert callable(simulate) and wuerfel_cvx.simulate is simulate\n"
            "print(simulate(Scene.named('tilted-drop'), steps=2).n_steps)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120, check=False)
    assert (result.returncode, result.stdout) == (0, "2\n"), result.stderr


# ---------------------------------------------------------------------------- simulate
@LINUX
@pytest.mark.subprocess
@pytest.mark.integration
def test_ctrl_c_during_start_up_is_one_line(tmp_path: Path) -> None:
    command = Command(["simulate", "tilted-drop", "--steps", "50"], tmp_path)
    command.wait_until(relay_started(command), "the Ctrl-C relay")  # cvxpy still importing
    command.press_ctrl_c()
    out, err = assert_stopped_cleanly(command)
    assert (out, err) == ("", "wuerfel-cvx: interrupted\n")


@LINUX
@pytest.mark.subprocess
@pytest.mark.integration
def test_ctrl_c_during_osqp_friction_solves_keeps_the_steps_done(tmp_path: Path) -> None:
    # OSQP installs its own SIGINT handler while it iterates; coulomb friction solves a
    # friction problem through cvxpy and OSQP in every step of the card house.
    steps = 2000
    command = Command(["simulate", "card-house", "--dt", "0.0166667", "--steps", str(steps),
                       "--friction-model", "coulomb", "--solver", "osqp", "--out", "run",
                       "--progress"], tmp_path)
    shown = re.compile(rf"(\d+)/{steps} ")  # the progress bar's "12/2000 "
    command.wait_until(lambda: any(int(done) >= 3 for done in shown.findall(command.stderr)),
                       "three steps")
    command.press_ctrl_c()
    _, err = assert_stopped_cleanly(command)
    last = err.strip().splitlines()[-1]
    match = re.fullmatch(rf"wuerfel-cvx: interrupted during step (\d+) of {steps}; kept the "
                         r"(\d+) steps done in (.+\.npz)", last)
    assert match, last
    before, kept = int(match[1]), int(match[2])
    assert before == kept + 1
    saved = Trajectory.load(tmp_path / match[3])
    assert saved.n_steps == kept and len(saved.metrics) == kept
    assert "solver_error" not in err


# ------------------------------------------------------------------------------ bench
SWEEP = """name = "ctrl-c"
[defaults]
duration = 6.0  # long enough that a Ctrl-C after the first row lands mid-sweep
reference = "none"
compare_every = 0
[[grid]]
scenes = ["tilted-drop", "stack-3", "stack-2"]
solvers = ["CLARABEL", "OSQP"]
tols = ["low", "default"]
"""


@LINUX
@pytest.mark.subprocess
@pytest.mark.integration
@pytest.mark.parametrize(("executor", "presses"), [
    pytest.param(["--jobs", "1"], 1, id="one-process"),
    pytest.param(["--jobs", "2"], 1, id="pool"),
    pytest.param(["--jobs", "2"], 2, id="pool-pressed-twice"),
    pytest.param(["--dask", "2"], 1, id="dask"),
])
def test_ctrl_c_in_a_sweep_keeps_its_rows_and_resume_runs_the_rest(
        executor: list[str], presses: int, tmp_path: Path) -> None:
    if executor[0] == "--dask":
        pytest.importorskip("distributed")
    suite_file = tmp_path / "ctrl-c.toml"
    suite_file.write_text(SWEEP)
    total = len(Suite.from_toml(suite_file).points)
    results = tmp_path / "out" / RESULTS_FILE
    args = ["bench", "--suite", str(suite_file), "--out", "out", "--no-progress", *executor]
    command = Command(args, tmp_path)
    command.wait_until(lambda: results.exists() and results.read_text().count("\n") >= 2,
                       "a first row")
    command.press_ctrl_c(presses)
    status, out, err = command.finish()
    failed = ([] if status == 130 or not results.exists() else
              schema.read_results(results).query("status != 'ok'")["error"].tolist())
    assert status == 130, (status, out, err, failed)
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert command.left_running() == [], "processes of the command left running"
    assert err.strip().splitlines()[-1] == (
        "wuerfel-cvx: interrupted; the finished rows are in out/results.csv, and the same "
        "command runs the rest")
    kept = schema.read_results(results)
    assert 1 <= len(kept) < total, "the Ctrl-C came too late to cut a point short"
    assert (kept["status"] == "ok").all(), kept["error"].dropna().tolist()

    resumed = subprocess.run([sys.executable, "-m", "wuerfel_cvx", *args], cwd=tmp_path,
                             capture_output=True, text=True, timeout=600, check=False)
    assert resumed.returncode == 0, resumed.stderr
    assert f"{len(kept)} of {total} rows done" in resumed.stderr
    assert f"{total - len(kept)} grid points run" in resumed.stdout
    frame = schema.read_results(results)
    assert sorted(frame["point_id"]) == sorted(p.point_id for p in
                                               Suite.from_toml(suite_file).points)
    assert (frame["status"] == "ok").all(), frame["error"].dropna().tolist()


# ------------------------------------------------------------------------- robustness
@LINUX
@pytest.mark.subprocess
@pytest.mark.integration
def test_ctrl_c_in_robustness_writes_no_report(tmp_path: Path) -> None:
    command = Command(["robustness", "--scenes", "200", "--fuzz", "0", "--out", "report.md"],
                      tmp_path)
    command.wait_until(lambda: "property sweep:" in command.stderr, "the property sweep")
    time.sleep(1.0)  # into the generated scenes' runs
    command.press_ctrl_c()
    _, err = assert_stopped_cleanly(command)
    assert err.strip().splitlines()[-1] == "wuerfel-cvx: interrupted; report.md not written"
    assert not (tmp_path / "report.md").exists()
