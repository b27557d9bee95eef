"""The friction targets: ``reports/friction/targets.md``.

Three measurements, each a run of a library scene:

* **ramps** (``friction-ramps`` at dt 1/240, 4.5 s): each box's acceleration down the ramp
  it falls onto, fitted once it lies flat on the ramp while it slides on it, against
  ``g (sin theta - mu cos theta)`` with the contact's ``mu = sqrt(mu_box mu_ramp)`` (a
  deceleration where ``mu > tan theta``: the boxes arrive sliding);
* **standing** (stacks, pyramids, the card house at dt 1/60 for 10 s, and the peers): the
  largest displacement of any box between the end of the settling time and the end of
  the run;
* **convergence**: the share of ``coulomb`` steps whose fixed point converged, over every
  ``coulomb`` run above (metrics column ``coulomb_converged``).

``python -m wuerfel_cvx.lab.bench.friction_targets measure --out DIR`` writes
``DIR/targets.csv``; ``report DIR/targets.csv --out DIR/targets.md`` renders it.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...errors import StepFailure
from ...scenes.library import named_scene
from ...scenes.scene import Scene
from ...simulate import simulate
from ...trajectory import Trajectory
from ..peers import available_peers, simulate_peer
from .markdown import format_number, markdown_table
from .report import provenance_line_of
from .sweep import record_provenance

RAMP_TOLERANCE = {"ccp": 0.03, "coulomb": 0.01}
"""Relative error allowed in a ramp's slide acceleration, per friction model."""
STANDING = 1e-4
"""Largest displacement (m) of a scene that stands: 0.1 mm."""
CONVERGED_SHARE = 0.99
"""Share of ``coulomb`` steps that must converge within the iteration limit."""
MODELS = ("ccp", "coulomb")
SOLVERS = ("CLARABEL", "OSQP", "PIQP")


@dataclass(frozen=True)
class StandingCase:
    """A scene that should stand: its run and the time it is given to settle (s)."""

    scene: str
    duration: float = 10.0
    settle: float = 1.0
    dt: float = 1.0 / 60.0
    coulomb_duration: float | None = None
    """A shorter run (s) for ``coulomb`` where its fixed point takes its iteration limit in
    every step (``None``: :attr:`duration`)."""

    def seconds(self, model: str) -> float:
        """The simulated time (s) of ``model``'s run (peers: ``model`` empty)."""
        if model == "coulomb" and self.coulomb_duration is not None:
            return self.coulomb_duration
        return self.duration


STANDING_CASES = (StandingCase("vertical-stack"), StandingCase("field-pyramid-10", settle=0.0),
                  StandingCase("field-pyramid-20", settle=0.0),
                  StandingCase("card-house", coulomb_duration=2.0))
"""The vertical stack starts with its boxes 0.1 m apart and the card house with its floors
2.3 mm apart (the source's placement): each is given 1 s to fall together.  The pyramids
start touching and are judged from the start.  ``coulomb`` runs the card house 2 s: its
fixed point takes many iterations a step there (several seconds of wall time a step)."""


def centres(trajectory: Trajectory) -> np.ndarray:
    """Centre of each box ``(states, boxes, 2)`` (m)."""
    return np.asarray(trajectory.points.reshape(trajectory.points.shape[0], -1, 4, 2).mean(
        axis=2), dtype=np.float64)


def displacement(trajectory: Trajectory, settle: float) -> float:
    """Largest distance (m) of a box centre from where it was at ``settle`` seconds."""
    path = centres(trajectory)
    start = min(int(round(settle / float(trajectory.info["dt"]))), path.shape[0] - 1)
    return float(np.linalg.norm(path[start:] - path[start], axis=-1).max())


RAMP_SETTLE = 0.1
"""Time (s) after a box lies flat on its ramp before its slide is fitted."""
FLAT = 1e-4
"""Angle (rad) within which a box's side is parallel to its ramp: it lies flat."""
STOPPED = 1e-3
"""Speed (m/s) below which a box has stopped sliding."""


def ramp_rows(trajectory: Trajectory, scene: Scene) -> list[dict[str, Any]]:
    """Per box: its ramp's angle and coefficient, the expected and fitted acceleration.

    Each box falls onto the ramp below it, lands on a corner and tips flat (it may roll
    over a corner first).  Its slide is fitted over the longest time it lies flat on that
    ramp and slides, less the first :data:`RAMP_SETTLE`; a box that never does (it rolls
    until it stops) has no fit.  The expected acceleration
    down the ramp is ``g (sin theta - mu cos theta)`` while it slides, also for
    ``mu > tan theta``, where it is a deceleration.
    """
    dt = float(trajectory.info["dt"])
    path = centres(trajectory)
    corners = trajectory.points.reshape(trajectory.points.shape[0], -1, 4, 2)
    velocities = trajectory.velocities.reshape(corners.shape).mean(axis=2)
    times = np.arange(path.shape[0]) * dt
    rows = []
    for box, body in enumerate(scene.bodies):
        table = _ramp_under(scene, box)
        mu = math.sqrt(body.friction * table.friction)
        theta = abs(table.angle)
        along = np.array([math.cos(table.angle), math.sin(table.angle)])
        offset = (path[:, box] - np.asarray(table.center)) @ along
        side = corners[:, box, 1] - corners[:, box, 0]
        tilt = np.arctan2(side[:, 1], side[:, 0]) - table.angle
        flat = np.abs((tilt + math.pi / 4) % (math.pi / 2) - math.pi / 4) <= FLAT
        on_ramp = np.abs(offset) <= 0.5 * table.size[0] - 0.5 * max(body.width, body.height)
        sliding = np.linalg.norm(velocities[:, box], axis=1) > STOPPED
        first, last = _longest_run(flat & on_ramp & sliding)
        first = min(first + int(round(RAMP_SETTLE / dt)), last)
        expected = 9.81 * (math.sin(theta) - mu * math.cos(theta))
        window = slice(first, last)
        enough = last - first > 8
        downhill = -np.sign(table.angle) * (offset - offset[min(first, len(offset) - 1)])
        rows.append({"box": box, "angle": theta, "mu": mu, "expected": expected,
                     "fitted": _fitted_acceleration(times[window], downhill[window])
                     if enough else math.nan,
                     "fit_from_s": first * dt, "fit_s": max(0, last - first) * dt})
    return rows


def _longest_run(mask: np.ndarray) -> tuple[int, int]:
    """``(start, stop)`` of the longest run of ``True`` in ``mask`` (``(0, 0)`` if none)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    if not edges.size:
        return 0, 0
    starts, stops = edges[0::2], edges[1::2]
    longest = int(np.argmax(stops - starts))
    return int(starts[longest]), int(stops[longest])


def _ramp_under(scene: Scene, box: int) -> Any:
    """The table nearest below box ``box``'s centre at the start."""
    centre = np.asarray(scene.bodies[box].center)
    return min(scene.tables, key=lambda table: _distance_to_top(table, centre))


def _distance_to_top(table: Any, point: np.ndarray) -> float:
    along = np.array([math.cos(table.angle), math.sin(table.angle)])
    normal = np.array([-along[1], along[0]])
    relative = point - np.asarray(table.center)
    height = relative @ normal - 0.5 * table.size[1]
    beyond = max(0.0, abs(relative @ along) - 0.5 * table.size[0])
    return math.inf if height < 0 else math.hypot(height, beyond)


def _fitted_acceleration(times: np.ndarray, distance: np.ndarray) -> float:
    design = np.column_stack([np.ones_like(times), times, 0.5 * times**2])
    return float(np.linalg.lstsq(design, distance, rcond=None)[0][2])


def _run(scene: str, dt: float, steps: int, model: str, solver: str) -> tuple[
        Trajectory | None, str]:
    """The run and ``"ok"``, or the trajectory up to a failure and the failure."""
    try:
        return simulate(scene, dt=dt, steps=steps, solver=solver, friction_model=model), "ok"
    except StepFailure as failure:
        return failure.trajectory, str(failure)


def measure(quick: bool = False, scenes: Sequence[str] = ()) -> Iterator[dict[str, Any]]:
    """Every target row: ramps per box, standing scenes per engine, with convergence.

    ``scenes``: only these scenes' rows (``friction-ramps`` or a standing case); all if empty.
    """
    scale = 0.1 if quick else 1.0
    if not scenes or "friction-ramps" in scenes:
        yield from _ramp_rows(scale)
    for case in STANDING_CASES:
        if not scenes or case.scene in scenes:
            yield from _standing_rows(case, scale)


def _ramp_rows(scale: float) -> Iterator[dict[str, Any]]:
    for model in MODELS:
        for solver in SOLVERS:
            started = time.perf_counter()
            trajectory, outcome = _run("friction-ramps", 1.0 / 240.0, int(1080 * scale),
                                       model, solver)
            seconds = time.perf_counter() - started
            for row in ramp_rows(trajectory, named_scene("friction-ramps")) if trajectory else []:
                yield {"kind": "ramp", "scene": "friction-ramps", "engine": "wuerfel_cvx",
                       "model": model, "solver": solver, "outcome": outcome,
                       "wall_s": seconds, **_convergence(trajectory), **row}


def _standing_rows(case: StandingCase, scale: float) -> Iterator[dict[str, Any]]:
    steps = int(round(case.duration * scale / case.dt))
    for model in MODELS:
        for solver in SOLVERS:
            started = time.perf_counter()
            trajectory, outcome = _run(case.scene, case.dt, int(round(
                case.seconds(model) * scale / case.dt)), model, solver)
            yield _standing_row(case, "wuerfel_cvx", model, solver, trajectory, outcome,
                                time.perf_counter() - started, scale)
    for engine in available_peers():
        started = time.perf_counter()
        peer = simulate_peer(engine, case.scene, case.dt, steps)
        yield _standing_row(case, engine.lower(), "", engine, peer, "ok",
                            time.perf_counter() - started, scale)


def _standing_row(case: StandingCase, engine: str, model: str, solver: str,
                  trajectory: Trajectory | None, outcome: str, seconds: float,
                  scale: float) -> dict[str, Any]:
    steps = 0 if trajectory is None else trajectory.n_steps
    moved = math.nan if trajectory is None else displacement(trajectory, case.settle * scale)
    penetration = (math.nan if trajectory is None or not steps
                   else float(trajectory.metrics["penetration_m"].max()))
    return {"kind": "standing", "scene": case.scene, "engine": engine, "model": model,
            "solver": solver, "outcome": outcome, "wall_s": seconds, "steps": steps,
            "duration_s": steps * case.dt,
            "moved": moved, "penetration": penetration, **_convergence(trajectory)}


def _convergence(trajectory: Trajectory | None) -> dict[str, Any]:
    """Steps of a ``coulomb`` run and how many converged (empty for other runs)."""
    if trajectory is None or "coulomb_converged" not in trajectory.metrics:
        return {"coulomb_steps": math.nan, "coulomb_converged": math.nan}
    converged = trajectory.metrics["coulomb_converged"].dropna()
    return {"coulomb_steps": len(converged), "coulomb_converged": int(converged.astype(bool).sum())}


PROVENANCE_FILE = "targets-provenance.json"
"""Beside ``targets.csv``: the physics fingerprint and code its rows were measured with."""


def render(frame: pd.DataFrame, provenance: str = "") -> str:
    """``targets.md`` from :func:`measure`'s rows; ``provenance``: their fingerprint line."""
    ramps = frame[frame["kind"] == "ramp"]
    standing = frame[frame["kind"] == "standing"]
    lines = ["# Friction targets", "",
             "Generated by `python -m wuerfel_cvx.lab.bench.friction_targets` (commands at the "
             "end); every number is measured by it.", "", *([provenance, ""] if provenance else []),
             "## Ramps (dt 1/240 s)", "",
             _ramp_table(ramps), "", "## Standing scenes (dt 1/60 s)", "",
             _standing_table(standing), "", "## Coulomb's fixed point", "",
             _convergence_text(frame), "", "## Commands", "",
             "    python -m wuerfel_cvx.lab.bench.friction_targets measure --out reports/friction",
             "    python -m wuerfel_cvx.lab.bench.friction_targets report "
             "reports/friction/targets.csv --out reports/friction/targets.md", ""]
    return "\n".join(lines)


def _ramp_table(ramps: pd.DataFrame) -> str:
    rows = []
    for record in ramps.to_dict("records"):
        expected, fitted = float(record["expected"]), float(record["fitted"])
        error = fitted / expected - 1.0
        if math.isnan(fitted):
            verdict, measured = "no flat slide to fit", "-"
        else:
            verdict = "met" if abs(error) <= RAMP_TOLERANCE[record["model"]] else "missed"
            measured = f"{format_number(fitted, 5)} (relative error {error:+.1e})"
        rows.append([record["model"], record["solver"], int(record["box"]),
                     format_number(record["angle"]), format_number(record["mu"]),
                     format_number(expected), measured,
                     f"{format_number(record['fit_from_s'])} + {format_number(record['fit_s'])}",
                     verdict])
    tolerances = ", ".join(f"{m} {100 * t:g} %" for m, t in RAMP_TOLERANCE.items())
    return markdown_table(["model", "solver", "box", "angle (rad)", "mu", "expected (m/s^2)",
                           "fitted (m/s^2)", "fitted over (s)", f"target ({tolerances})"],
                          rows, "llrrrrrll")


def _standing_table(standing: pd.DataFrame) -> str:
    rows = [[record["scene"], record["engine"],
             record["model"] if isinstance(record["model"], str) else "-", record["solver"],
             format_number(record["duration_s"]),
             format_number(record["moved"]), format_number(record["penetration"]),
             _verdict(record), format_number(record["wall_s"]), record["outcome"]]
            for record in standing.to_dict("records")]
    return markdown_table(["scene", "engine", "model", "solver", "run (s)",
                           "moved after settling (m)", "deepest penetration (m)", "<= 0.1 mm",
                           "wall (s)", "outcome"], rows, "llllrrrlrl")


def _verdict(record: Mapping[Any, Any]) -> str:
    """``stands`` or ``moves``; ``failed`` for a run that stopped (its motion is not judged)."""
    if record["outcome"] != "ok":
        return "failed"
    return "stands" if float(record["moved"]) <= STANDING else "moves"


def _convergence_text(frame: pd.DataFrame) -> str:
    steps = float(np.nansum(frame.drop_duplicates(["scene", "model", "solver", "engine"])[
        "coulomb_steps"].to_numpy(dtype=float)))
    converged = float(np.nansum(frame.drop_duplicates(["scene", "model", "solver", "engine"])[
        "coulomb_converged"].to_numpy(dtype=float)))
    if not steps:
        return "No `coulomb` run recorded its convergence."
    share = converged / steps
    verdict = "met" if share >= CONVERGED_SHARE else "missed"
    return (f"{int(converged)} of {int(steps)} `coulomb` steps converged within the "
            f"iteration limit ({100 * share:.2f} %; target {100 * CONVERGED_SHARE:g} %: "
            f"{verdict}).")


def main(argv: Sequence[str] | None = None) -> int:
    """``measure`` (write targets.csv) or ``report`` (write targets.md)."""
    parser = argparse.ArgumentParser(prog="python -m wuerfel_cvx.lab.bench.friction_targets")
    commands = parser.add_subparsers(dest="command", required=True)
    run = commands.add_parser("measure", help="run the target scenes, write targets.csv")
    run.add_argument("--out", type=Path, required=True, help="directory to write into")
    run.add_argument("--quick", action="store_true", help="a tenth of every run (a check)")
    run.add_argument("--scene", action="append", default=[],
                     help="measure only this scene's rows (repeatable; default: all)")
    report = commands.add_parser("report", help="write targets.md from targets.csv")
    report.add_argument("csv", type=Path)
    report.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    if args.command == "measure":
        args.out.mkdir(parents=True, exist_ok=True)
        (args.out / PROVENANCE_FILE).unlink(missing_ok=True)  # every row is measured anew
        record_provenance(args.out / PROVENANCE_FILE)
        rows = []
        for row in measure(args.quick, args.scene):
            rows.append(row)
            print(f"{row['kind']} {row['scene']} {row['engine']} {row['model']} "
                  f"{row['solver']}: {row['outcome']} ({row['wall_s']:.0f} s)", flush=True)
            pd.DataFrame(rows).to_csv(args.out / "targets.csv", index=False)
        return 0
    frame = pd.read_csv(args.csv, keep_default_na=False, na_values=[""])
    args.out.write_text(render(frame, provenance_line_of(args.csv.parent / PROVENANCE_FILE)),
                        encoding="utf-8")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
