"""Sweeps on a Dask cluster: the pool's rows, scenes as data, a killed worker, the flags."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pandas as pd
import pytest

from wuerfel_cvx import Scene
from wuerfel_cvx.cli import main
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.lab.bench import schema
from wuerfel_cvx.lab.bench.dask_sweep import DaskCluster
from wuerfel_cvx.lab.bench.runner import PointResult
from wuerfel_cvx.lab.bench.suite import GridPoint, Suite
from wuerfel_cvx.lab.bench.sweep import RESULTS_FILE, run_sweep

pytestmark = pytest.mark.integration

SUITE_TOML = """name = "{name}"
[defaults]
duration = {duration}
dts = [0.01]
compare_every = {compare_every}
reference = "{reference}"
[[grid]]
scenes = {scenes}
solvers = ["CLARABEL", "OSQP"]
tols = {tols}
"""


def suite_file(folder: Path, name: str, scenes: list[str], *, duration: float = 0.05,
               tols: tuple[str, ...] = ("default",), reference: str = "dt/8",
               compare_every: int = 1) -> Path:
    """A suite of CLARABEL and OSQP points on ``scenes``, written to ``folder``."""
    path = folder / f"{name}.toml"
    scene_list = "[" + ", ".join(f'"{scene}"' for scene in scenes) + "]"
    tol_list = "[" + ", ".join(f'"{tol}"' for tol in tols) + "]"
    path.write_text(SUITE_TOML.format(name=name, duration=duration, scenes=scene_list,
                                      tols=tol_list, reference=reference,
                                      compare_every=compare_every))
    return path


def cells(results: Path) -> pd.DataFrame:
    """The results file as its written text, one row per point id (bit-exact cells)."""
    frame = pd.read_csv(results, dtype=str, keep_default_na=False)
    assert frame["point_id"].is_unique
    return frame.set_index("point_id").sort_index()


def physics(frame: pd.DataFrame) -> pd.DataFrame:
    """Every column not read off a clock: physics, equal to the bit between executors."""
    return frame.drop(columns=[column for column in frame.columns
                               if column in schema.CLOCK_COLUMNS])


@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    """The two-worker LocalCluster that ``--dask 2`` starts, shared by this module.

    Its client, and the notes it gave (the workers, the dashboard).
    """
    pytest.importorskip("distributed")
    from wuerfel_cvx.lab.bench.dask_sweep import dask_executor

    notes: list[str] = []
    with dask_executor(DaskCluster(workers=2), notes.append) as executor:
        yield SimpleNamespace(client=executor.client, notes=notes)


@pytest.mark.subprocess  # worker processes
def test_dask_rows_equal_the_process_pools_to_the_bit(
        tmp_path: Path, cluster: Any, capsys: pytest.CaptureFixture[str]) -> None:
    assert "dask: 2 workers at tcp://" in cluster.notes[0]
    assert cluster.notes[1].startswith("dask dashboard: http://")
    suite = suite_file(tmp_path, "equal", ["tilted-drop", "resting-square", "no-such-scene"])
    pool, dask = tmp_path / "pool", tmp_path / "dask"
    assert main(["bench", "--suite", str(suite), "--out", str(pool), "--jobs", "2",
                 "--no-progress"]) == 0
    capsys.readouterr()
    assert main(["bench", "--suite", str(suite), "--out", str(dask), "--scheduler",
                 cluster.client.scheduler.address, "--no-progress"]) == 0
    assert "dask: 2 workers at tcp://" in capsys.readouterr().err
    by_pool, by_dask = cells(pool / RESULTS_FILE), cells(dask / RESULTS_FILE)
    assert list(by_dask.index) == sorted(p.point_id for p in Suite.from_toml(suite).points)
    assert (by_dask.loc[by_dask["scene"] != "no-such-scene", "status"] == "ok").all()
    assert by_dask.loc[by_dask["scene"] == "no-such-scene", "error"].str.contains(
        "InputError").all()
    pd.testing.assert_frame_equal(physics(by_dask), physics(by_pool))
    # The clocks did run: the rows are not copies.
    assert (by_dask["total_wall_time"] != by_pool["total_wall_time"]).any()
    series = sorted(path.name for path in (pool / "series").iterdir())
    assert series == sorted(path.name for path in (dask / "series").iterdir())
    assert len(series) == 4  # the error rows have none
    for name in series:
        pd.testing.assert_frame_equal(
            physics(pd.read_csv(dask / "series" / name, dtype=str)),
            physics(pd.read_csv(pool / "series" / name, dtype=str)))
    references = sorted(path.name for path in (pool / "references").iterdir())
    assert references == sorted(path.name for path in (dask / "references").iterdir())
    assert len(references) == 2  # tilted-drop and resting-square, written by the client
    for name in references:
        assert (dask / "references" / name).read_bytes() == \
            (pool / "references" / name).read_bytes()


@pytest.mark.subprocess  # worker processes
def test_scenes_travel_as_data_and_a_dask_sweep_resumes(
        tmp_path: Path, cluster: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    # The scene file exists only under the client's working directory: a worker that
    # looked for it by path (from a working directory of its own) would not find it.
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "drop.toml").write_text(Scene.named("tilted-drop").to_toml())
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(tmp_path)
    started_in = cluster.client.run(os.getcwd)
    cluster.client.run(os.chdir, str(elsewhere))
    try:
        suite = Suite.from_toml(suite_file(tmp_path, "data", ["scenes/drop.toml"]))
        dask = DaskCluster(scheduler=cluster.client.scheduler.address)
        summary = run_sweep(suite, tmp_path / "out", dask=dask, progress=False,
                            echo=lambda _: None)
        frame = schema.read_results(summary.results)
        assert (frame["status"] == "ok").all(), frame["error"].tolist()
        assert frame["trajectory_error"].notna().all()  # the dt/8 reference ran too
        # Resume: the last row torn mid-write is run again, the other kept as it was.
        lines = summary.results.read_text().splitlines(keepends=True)
        summary.results.write_text("".join(lines[:-1]) + lines[-1][:30])
        again = run_sweep(suite, tmp_path / "out", dask=dask, progress=False,
                          echo=lambda _: None)
    finally:
        for address, folder in started_in.items():
            cluster.client.run(os.chdir, folder, workers=[address])
    assert (again.ran, again.skipped_done) == (1, 1)
    resumed = cells(summary.results)
    assert len(resumed) == 2 and (resumed["status"] == "ok").all()
    assert resumed.loc[frame["point_id"][0], "finished_at"] == frame["finished_at"][0]


@pytest.mark.subprocess  # worker processes, one of them killed
def test_a_killed_worker_loses_no_row_and_repeats_none(tmp_path: Path, cluster: Any) -> None:
    suite = Suite.from_toml(suite_file(
        tmp_path, "killme", ["tilted-drop", "resting-square", "stack-2"], duration=0.3,
        tols=("low", "default"), reference="none", compare_every=0))
    out = tmp_path / "out"
    results = out / RESULTS_FILE
    outcome: dict[str, Any] = {}

    def sweep() -> None:
        try:
            outcome["summary"] = run_sweep(
                suite, out, dask=DaskCluster(scheduler=cluster.client.scheduler.address),
                progress=False, echo=lambda _: None)
        except BaseException as exc:  # handed to the test's thread
            outcome["error"] = exc

    runner = threading.Thread(target=sweep)
    runner.start()
    killed: list[Any] = []
    written = 0
    deadline = time.monotonic() + 120
    while not killed and time.monotonic() < deadline and runner.is_alive():
        written = results.read_text().count("\n") - 1 if results.exists() else 0
        busy = [address for address, keys in cluster.client.processing().items() if keys]
        if written >= 2 and busy:  # some rows in, a point running on that worker
            pids = cluster.client.run(os.getpid, workers=busy[:1])
            os.kill(pids[busy[0]], signal.SIGKILL)
            killed.append(busy[0])
        time.sleep(0.02)
    runner.join(timeout=180)
    assert not runner.is_alive() and "error" not in outcome, outcome.get("error")
    assert killed, "the sweep ended before a worker could be killed mid-point"
    frame = schema.read_results(results)
    assert written < len(suite.points), "the kill came too late to lose anything"
    assert frame["point_id"].is_unique
    assert sorted(frame["point_id"]) == sorted(p.point_id for p in suite.points)
    assert (frame["status"] == "ok").all(), frame["error"].dropna().tolist()
    assert outcome["summary"].ran == len(suite.points)


def test_the_flags_without_the_extra_name_it_in_one_line(
        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(__import__("sys").modules, "distributed", None)  # import fails
    for flag in (["--dask", "2"], ["--scheduler", "tcp://127.0.0.1:8786"]):
        assert main(["bench", "--suite", "smoke", *flag]) == 2
        error = capsys.readouterr().err
        assert error.count("\n") == 1
        assert f"{flag[0]}: needs Dask" in error and 'pip install "wuerfel_cvx[dask]"' in error


@pytest.mark.parametrize(("flags", "message"), [
    (["--dask", "0"], "--dask: must be at least 1, got 0"),
    (["--dask", "2", "--scheduler", "tcp://h:1"], "--dask: give either"),
    (["--dask", "2", "--jobs", "2"], "--jobs: give --jobs or a Dask cluster"),
])
def test_bad_cluster_flags_are_input_errors(flags: list[str], message: str, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed")
    assert main(["bench", "--suite", "smoke", "--out", str(tmp_path), *flags]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and message in error


def test_an_unreachable_scheduler_is_an_input_error(tmp_path: Path) -> None:
    dask = pytest.importorskip("dask")
    suite = Suite.from_toml(suite_file(tmp_path, "far", ["resting-square"]))
    with dask.config.set({"distributed.comm.timeouts.connect": "0.5s"}), \
            pytest.raises(InputError, match="--scheduler: cannot connect"):
        run_sweep(suite, tmp_path / "out", dask=DaskCluster(scheduler="tcp://127.0.0.1:9"),
                  progress=False, echo=lambda _: None)


class _FailedTask:
    """What ``as_completed`` hands over for a task that failed with ``failure``."""

    status = "error"

    def __init__(self, failure: BaseException) -> None:
        self.failure = failure

    def exception(self) -> BaseException:
        return self.failure

    def result(self) -> Any:
        raise self.failure


def test_a_point_that_kills_its_workers_becomes_an_error_row_and_other_failures_stop(
) -> None:
    distributed = pytest.importorskip("distributed")
    from wuerfel_cvx.lab.bench.dask_sweep import _point_result

    point = GridPoint("s", "stack-2", "velocity", "OSQP", "default", 0.01, 0.1)
    died = distributed.KilledWorker("point-1", SimpleNamespace(address="tcp://127.0.0.1:1"), 3)
    result = _point_result(_FailedTask(died), point)  # type: ignore[arg-type]
    assert isinstance(result, PointResult) and result.series is None
    assert result.row["point_id"] == point.point_id and result.row["status"] == "error"
    assert result.row["error"].startswith("KilledWorker: ")
    missing = ModuleNotFoundError("No module named 'wuerfel_cvx'")  # the cluster's failure
    with pytest.raises(ModuleNotFoundError):
        _point_result(_FailedTask(missing), point)  # type: ignore[arg-type]
