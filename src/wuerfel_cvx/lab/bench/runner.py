"""Run one grid point, or one reference, and turn the result into a results row.

Every failure of a grid point becomes a row: a failed step gives ``status = "failed"`` with
the step and the solver's status, anything else (an unknown scene, a bad tolerance) gives
``status = "error"``.  Nothing here raises for a bad configuration.
"""

from __future__ import annotations

import datetime as dt_module
import hashlib
import platform
import time
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...errors import StepFailure
from ...formulations import StepQP
from ...scenes.geometry import FloatArray
from ...scenes.scene import Scene
from ...simulate import ASLEEP, resolve_scene, simulate
from ...solve.kkt import EXACT_OUTCOMES
from ...solve.paths import StepSolution, solve_step_qp
from ...solve.registry import SOLVERS
from ...step.metrics import deepest_overlap, largest_corner_distance, total_energy
from ...step.model import State
from ...trajectory import Trajectory
from ...versions import package_version
from ..peers import peer_version, simulate_peer
from . import schema
from .floors import bare_calls, kkt_factorization_seconds
from .friction_summary import column_max, friction_summary
from .suite import (
    DEFAULT_FRICTION_MODEL,
    REFERENCE_REFINEMENT,
    REFERENCE_SOLVER,
    REFERENCE_TOL,
    GridPoint,
    ReferenceKey,
)


@dataclass(frozen=True)
class Reference:
    """A reference trajectory sampled at the grid point's instants ``k dt``."""

    points: FloatArray
    """Corner positions ``(m + 1, 4 n, 2)`` (m) at ``t = k dt``, ``k = 0..m``."""
    complete: bool
    """False when the reference run itself failed before the end."""
    detail: str = ""


def reference_file_name(key: ReferenceKey) -> str:
    """File name under ``<out>/references/`` for a reference key.

    The default friction model is left out of the name and its digest, so a reference's
    file keeps the name it had before suites had friction models.
    """
    scene, formulation, dt, duration, friction_model = key
    named = key[:4] if friction_model == DEFAULT_FRICTION_MODEL else key
    digest = hashlib.sha1(repr(named).encode("utf-8")).hexdigest()[:10]
    name = Path(scene).stem if scene.endswith(".toml") or "/" in scene else scene  # a file
    model = "" if friction_model == DEFAULT_FRICTION_MODEL else f"-{friction_model}"
    return f"{name}-{formulation}{model}-dt{dt:g}-T{duration:g}-{digest}.npz"


def compute_reference(key: ReferenceKey, path: Path) -> Path:
    """Run the dt/8 reference for ``key`` and save it to ``path`` (``.npz``)."""
    return save_reference(run_reference(key), path)


def run_reference(key: ReferenceKey, scene: Scene | None = None) -> Reference:
    """Run the dt/8 reference for ``key``: ``scene`` given as data, or resolved from the key.

    The run uses fixed tables, five rods, :data:`REFERENCE_SOLVER` at :data:`REFERENCE_TOL`
    and the key's friction model.  A failed reference is returned too, marked incomplete,
    so the points that need it say so.
    """
    scene_name, formulation, dt, duration, friction_model = key
    fine_dt = dt / REFERENCE_REFINEMENT
    steps = max(1, round(duration / dt)) * REFERENCE_REFINEMENT
    detail = ""
    try:
        trajectory = simulate(scene_name if scene is None else scene, dt=fine_dt, steps=steps,
                              solver=REFERENCE_SOLVER, formulation=formulation,
                              tol=REFERENCE_TOL, friction_model=friction_model)
        complete = True
    except StepFailure as failure:
        assert failure.trajectory is not None
        trajectory, complete, detail = failure.trajectory, False, str(failure)
    return Reference(trajectory.points[::REFERENCE_REFINEMENT], complete, detail)


def save_reference(reference: Reference, path: Path) -> Path:
    """Write ``reference`` to ``path`` (``.npz``), atomically; returns ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(path.name + ".part.npz")
    np.savez(temporary, points=reference.points, complete=np.array(reference.complete),
             detail=np.array(reference.detail))
    temporary.replace(path)  # atomic: a killed sweep never leaves half a reference
    return path


def load_reference(path: Path) -> Reference:
    """Read a reference written by :func:`compute_reference`."""
    with np.load(path, allow_pickle=False) as data:
        return Reference(points=data["points"], complete=bool(data["complete"]),
                         detail=str(data["detail"]))


@cache
def machine() -> dict[str, str]:
    """CPU, Python and package versions of this process, as stored in every row."""
    return {"cpu": _cpu_name(), "python_version": platform.python_version(),
            "package_version": package_version("wuerfel_cvx"),
            "cvxpy_version": package_version("cvxpy")}


@dataclass(frozen=True)
class PointResult:
    """What one grid point gives: its results row and its per-step series."""

    row: dict[str, Any]
    """The results row (see :mod:`wuerfel_cvx.lab.bench.schema`)."""
    series: pd.DataFrame | None
    """Per-step metrics in :data:`schema.SERIES_COLUMNS`; ``None`` for an error row."""


def run_point(point: GridPoint, reference: Reference | None,
              series_dir: Path | None = None, scene: Scene | None = None) -> dict[str, Any]:
    """Run one grid point and return its results row (never raises for a bad config).

    The per-step series goes to ``series_dir`` when one is given.
    """
    result = measure_point(point, reference, scene)
    if series_dir is not None:
        write_series(result, series_dir)
    return result.row


def measure_point(point: GridPoint, reference: Reference | None,
                  scene: Scene | None = None) -> PointResult:
    """Run one grid point, writing nothing: its row and series (never raises for a bad config).

    ``scene`` is the point's scene as data; without it, ``point.scene_input`` is resolved
    here.
    """
    base = _configuration(point)
    try:
        scene = resolve_scene(point.scene_input if scene is None else scene)  # loaded once
        base["n_squares"] = scene.n_boxes
        started = time.perf_counter()
        trajectory, failure, disagreement, last_qp = _simulate(point, scene)
        call_seconds = time.perf_counter() - started
    except Exception as exc:  # any configuration error becomes an error row
        return PointResult(error_row(point, exc, base), None)
    row = {**base, **_outcome(trajectory, failure), **_timing(trajectory, point),
           "kkt_factor_time": None if last_qp is None else kkt_factorization_seconds(last_qp),
           **_call_timing(trajectory, call_seconds),
           **_accuracy(trajectory, point, reference),
           **friction_summary(trajectory, peer=point.engine != "wuerfel_cvx"),
           **_polish_summary(trajectory), **_bare_call_floor(point, scene, failure),
           "reference_disagreement": disagreement}
    series = trajectory.metrics.reindex(columns=list(schema.SERIES_COLUMNS))
    return PointResult(schema.new_row(**row), series)


def error_row(point: GridPoint, exc: BaseException,
              configuration: dict[str, Any] | None = None) -> dict[str, Any]:
    """The ``status = "error"`` row of a point that could not run, naming ``exc``."""
    base = _configuration(point) if configuration is None else configuration
    return schema.new_row(**base, status="error", error=_message(exc), success=False,
                          verified=False, steps_completed=0)


def write_series(result: PointResult, series_dir: Path) -> None:
    """Write the point's per-step series under ``series_dir`` (nothing for an error row)."""
    if result.series is None:
        return
    path = series_dir / schema.series_file_name(str(result.row["point_id"]))
    path.parent.mkdir(parents=True, exist_ok=True)
    result.series.to_csv(path, index=False)


def _simulate(point: GridPoint, scene: Scene
              ) -> tuple[Trajectory, StepFailure | None, float | None, StepQP | None]:
    """Run the point on ``scene``, its loaded scene.

    Returns the trajectory, the failure (a failed step returns the partial trajectory), the
    largest disagreement with the reference solver, and the last QP solved (``None`` for a
    peer).
    """
    worst = [0.0]
    compared = [0]
    last: list[StepQP | None] = [None]
    started = time.perf_counter()

    def compare(step: int, qp: StepQP, solution: StepSolution) -> None:
        last[0] = qp
        if time.perf_counter() - started > point.time_limit:
            raise StepFailure(step, point.solver, "time_limit",
                              f"grid point stopped after {point.time_limit:g} s of wall time")
        if point.compare_every and step % point.compare_every == 0:
            try:
                best = solve_step_qp(qp, REFERENCE_SOLVER, REFERENCE_TOL, step=step)
            except StepFailure:
                return  # the reference solver could not solve this QP: no comparison
            worst[0] = max(worst[0], float(np.max(np.abs(solution.x - best.x))))
            compared[0] += 1

    try:
        if point.engine != "wuerfel_cvx":
            trajectory = simulate_peer(point.solver, scene, point.dt, point.steps)
        else:
            trajectory = simulate(scene, steps=point.steps, observer=compare,
                                  settings=point.settings())
    except StepFailure as failure:
        if failure.trajectory is None:
            raise
        return failure.trajectory, failure, worst[0] if compared[0] else None, last[0]
    return trajectory, None, worst[0] if compared[0] else None, last[0]


def _configuration(point: GridPoint) -> dict[str, Any]:
    return {
        "suite": point.suite, "point_id": point.point_id, "scene": point.scene,
        "engine": point.engine, "formulation": point.formulation, "solver": point.solver,
        "tol": point.tol, "dt": point.dt, "duration": point.duration, "steps": point.steps,
        "table_mass": point.table_mass, "extra_rod": point.extra_rod, "sleep": point.sleep,
        "islands": point.islands, "friction_model": point.friction_model,
        "solve_path": point.solve_path, "polish": point.polish,
        "reuse_active_sets": point.reuse_active_sets,
        "solver_version": _solver_version(point.solver), **machine(),
        "finished_at": dt_module.datetime.now(dt_module.UTC).isoformat(timespec="seconds"),
        "reference_kind": point.reference_label,
    }


def _outcome(trajectory: Trajectory, failure: StepFailure | None) -> dict[str, Any]:
    metrics = trajectory.metrics
    completed = len(metrics)
    statuses = metrics["status"].astype(str)
    claimed = bool(statuses.isin(["optimal", "peer", ASLEEP]).all()) and failure is None
    verified_steps = metrics["verified"].astype("boolean")
    if bool(verified_steps.isna().all()) and completed:  # peers: nothing to verify
        verified: bool | None = None
        fraction = None
    else:
        verified = bool(verified_steps.fillna(False).all()) and failure is None
        fraction = float(verified_steps.fillna(False).mean()) if completed else 0.0
    outcome: dict[str, Any] = {
        "status": "ok" if failure is None else "failed", "steps_completed": completed,
        "success": claimed, "verified": verified, "verified_fraction": fraction,
    }
    if failure is not None:
        outcome |= {"error": _message(failure), "failed_step": failure.step}
    return outcome


def _polish_summary(trajectory: Trajectory) -> dict[str, Any]:
    """The run's polish columns: how often answers were polished, why not, and pushes.

    Counted over the steps that solved a QP (their ``polish`` is ``polished``, ``kept`` or
    ``rejected (reason)``); empty for a peer or a run recorded before polishing.
    """
    metrics = trajectory.metrics
    if "polish" not in metrics.columns:
        return {}
    solved = metrics[metrics["status"].astype("string").ne(ASLEEP)]
    outcomes = solved["polish"].astype("string").dropna()
    outcomes = outcomes[outcomes.ne("")]
    summary: dict[str, Any] = {
        "max_push_at_distance": column_max(metrics, "push_at_distance_Ns"),
        "max_push_gap_product": column_max(metrics, "push_gap_product_Nsm")}
    if not len(outcomes) or outcomes.eq("kept").all():
        return summary
    rejected = outcomes[outcomes.str.startswith("rejected")]
    reasons = rejected.str.extract(r"\((.*)\)", expand=False).fillna("").value_counts()
    return summary | {
        "polished_fraction": float(outcomes.isin(list(EXACT_OUTCOMES)).mean()),
        "reused_fraction": float(outcomes.eq("reused").mean()),
        "polish_rejected_steps": len(rejected),
        "polish_rejections": ", ".join(f"{reason}: {count}" for reason, count in reasons.items())
        or None}


def _call_timing(trajectory: Trajectory, seconds: float) -> dict[str, Any]:
    """What a user waits for: the whole ``simulate`` call's wall time per step (s), split.

    Set-up, every step's contact search, build, solve, check and update, the metrics and
    the recording; beside it, its ratio to the solver's own mean time per step, and the
    mean time per step of each stage (:data:`~wuerfel_cvx.lab.bench.schema.STAGE_TIME_COLUMNS`),
    which add up to the call's (a peer's run has only its step and solver times).
    """
    metrics = trajectory.metrics
    steps = len(metrics)
    if steps == 0:
        return {}
    per_step = seconds / steps
    solver = metrics["solver_time_s"].to_numpy(dtype=float)
    own = float(np.nanmean(solver)) if np.isfinite(solver).any() else np.nan
    stages = {f"{stage}_time_per_step": _nan_mean(metrics[f"{stage}_time_s"])
              for stage in ("search", "build", "solve", "polish", "update", "record")}
    return {"call_wall_time_per_step": per_step,
            "call_over_solver_mean": per_step / own if own > 0 else np.nan,
            **stages, "solver_time_per_step_mean": own,
            "outside_steps_time_per_step": per_step - float(metrics["step_time_s"].mean())}


def _bare_call_floor(point: GridPoint, scene: Scene,
                     failure: StepFailure | None) -> dict[str, Any]:
    """The floor under the call / solver ratio (:func:`.floors.bare_calls`), if asked for.

    Only for a completed point run with the default settings (its row is in the report's
    table of the default run).
    """
    if not (point.bare_call_floor and point.runs_defaults and failure is None):
        return {}
    floor = bare_calls(scene, point.settings(), point.steps)
    return {"bare_call_time_per_step": floor.per_step,
            "bare_call_over_solver": floor.over_solver}


def _nan_mean(column: pd.Series) -> float:
    """The mean of a metrics column's finite values; NaN when it has none (a peer's stage)."""
    values = column.to_numpy(dtype=float)
    return float(np.nanmean(values)) if np.isfinite(values).any() else np.nan


def _timing(trajectory: Trajectory, point: GridPoint) -> dict[str, Any]:
    metrics = trajectory.metrics
    if len(metrics) == 0:
        return {}
    step = metrics["step_time_s"].to_numpy(dtype=float)
    solver = metrics["solver_time_s"].to_numpy(dtype=float)
    simulated = len(metrics) * point.dt
    ran = solver > 0  # a reused step's solver time is 0: no solver ran, no ratio
    ratio = np.divide(step, solver, out=np.full_like(step, np.nan), where=ran)
    return {
        "wall_time_per_step_median": float(np.median(step)),
        "wall_time_per_step_p90": float(np.percentile(step, 90)),
        "solver_time_per_step_median": _nan_median(solver),
        "modelling_time_per_step_median": _nan_median(step - solver),
        "step_over_solver_median": _nan_median(ratio),
        "wall_time_per_simulated_second": float(step.sum() / simulated),
        "total_wall_time": float(step.sum()),
        "n_variables": _int_max(metrics["n_variables"]),
        "n_equalities": _int_max(metrics["n_equalities"]),
        "n_inequalities": _int_max(metrics["n_inequalities"]),
        "n_contacts_max": _int_max(metrics["n_contacts"]),
    }


def _accuracy(trajectory: Trajectory, point: GridPoint,
              reference: Reference | None) -> dict[str, Any]:
    metrics = trajectory.metrics
    accuracy: dict[str, Any] = {}
    if len(metrics):
        energy = metrics["total_energy_J"].to_numpy(dtype=float)
        initial = _initial_energy(trajectory)
        with_start = np.concatenate([[initial], energy])
        model = trajectory.model()
        assert model is not None, "every run records its scene"
        accuracy |= {
            "max_rod_drift": float(metrics["rod_drift"].max()),
            "max_penetration": float(metrics["penetration_m"].max()),
            "max_overlap_depth": max(deepest_overlap(model, points)
                                     for points in trajectory.points[1:len(metrics) + 1]),
            "energy_gain": float(np.max(energy) - initial),
            "max_step_energy_rise": float(np.max(np.diff(with_start))),
        }
    if point.reference == "rest":
        accuracy["trajectory_error"] = largest_corner_distance(trajectory.points,
                                                                trajectory.points[:1])
    elif point.reference == "settled":
        settled = round(point.settle / point.dt)
        if settled < len(trajectory.points):  # a run that failed before has no error
            after = trajectory.points[settled:]
            accuracy["trajectory_error"] = largest_corner_distance(after, after[:1])
    elif point.reference == "dt/8" and reference is not None:
        if reference.complete:
            accuracy["trajectory_error"] = largest_corner_distance(trajectory.points,
                                                                    reference.points)
        else:
            detail = " ".join(reference.detail.split())[:160]
            accuracy["reference_kind"] = f"dt/8 (reference failed: {detail})"
    return accuracy


def _initial_energy(trajectory: Trajectory) -> float:
    model = trajectory.model()
    assert model is not None, "every run records its scene"
    return total_energy(model, State(trajectory.points[0], trajectory.velocities[0]))


def _nan_median(values: FloatArray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else None


def _int_max(column: pd.Series) -> int | None:
    values = pd.to_numeric(column, errors="coerce").dropna()
    return int(values.max()) if len(values) else None


def _message(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}"[:500]


def _solver_version(solver: str) -> str:
    if solver in SOLVERS:
        return SOLVERS[solver].version()
    try:
        return peer_version(solver)
    except Exception:  # an unknown name: the row will carry the error itself
        return "unknown"


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"
