"""Measure the peer engines on a 20-box stack with friction 0.6 (docs/peers-friction.md).

    python docs/peers_friction_stack.py            # every installed engine
    python docs/peers_friction_stack.py --mu 0     # the frictionless stack

Library scene ``stack-20`` (unit squares of 1 kg on the floor) with ``friction = mu`` on
every square and on the floor, dt = 1/60 s, 10 s.  Each engine runs with the matched
settings of :mod:`wuerfel_cvx.lab.peers`; the Box2D engines also with sleep turned off.
Printed per run (one Markdown table row):

* drift: the largest horizontal displacement (m) of any square's centre from its start;
* penetration: the deepest corner penetration (m) over the run (the package's metric),
  the time it happens, and the deepest in the last second;
* gap: the largest vertical gap (m) between a square's lowest corner and the highest
  corner of the one below (the floor's top for the first) over the last second, while
  the stack is upright;
* toppled: the first time (s) at which a square's centre is more than half a side
  (0.5 m) off its start, when it is off the square below; "no" otherwise;
* time per step: median wall time of the engine's step call (us);
* for Box2D with sleep on: the time from which every square sleeps to the end, if any.
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
from typing import Any

import numpy as np

from wuerfel_cvx import Scene
from wuerfel_cvx.lab.peers import available_peers, peer_version, simulate_peer
from wuerfel_cvx.lab.peers._common import run_peer
from wuerfel_cvx.trajectory import Trajectory

DT = 1.0 / 60.0
DURATION = 10.0
TOPPLE_OFFSET = 0.5  # m: half a side, the square is off the one below


def stack(mu: float) -> Scene:
    """``stack-20`` with friction ``mu`` on every square and the floor."""
    scene = Scene.named("stack-20")
    return dataclasses.replace(
        scene, squares=tuple(dataclasses.replace(s, friction=mu) for s in scene.squares),
        tables=tuple(dataclasses.replace(t, friction=mu) for t in scene.tables))


def measure(traj: Trajectory) -> dict[str, Any]:
    """The drift, penetration, gap, topple time and step time of a run."""
    n = traj.points.shape[0]
    corners = traj.points.reshape(n, -1, 4, 2)
    centers = corners.mean(axis=2)
    offset = np.abs(centers[:, :, 0] - centers[0, :, 0])
    toppled = np.flatnonzero(offset.max(axis=1) > TOPPLE_OFFSET)
    last = traj.times >= traj.times[-1] - 1.0
    bottoms = corners[last, :, :, 1].min(axis=2)
    tops = corners[last, :, :, 1].max(axis=2)
    floor_top = float(traj.table_points[:, 1].max())
    below = np.concatenate([np.full((bottoms.shape[0], 1), floor_top), tops[:, :-1]], axis=1)
    gaps = bottoms - below
    return {
        "drift_m": float(offset.max()),
        "penetration_m": float(traj.metrics["penetration_m"].max()),
        "penetration_at_s": float(traj.metrics["time_s"][traj.metrics["penetration_m"].idxmax()]),
        "late_penetration_m": float(traj.metrics["penetration_m"][last[1:]].max()),
        "gap_m": float(gaps.max()) if toppled.size == 0 else float("nan"),
        "toppled_s": float(traj.times[toppled[0]]) if toppled.size else None,
        "step_us": 1e6 * float(traj.metrics["solver_time_s"].median()),
    }


class _Watched:
    """A Box2D world that records the time (s) from which all its bodies sleep."""

    def __init__(self, world: Any) -> None:
        self.world, self.time, self.asleep_from = world, 0.0, None

    def step(self) -> None:
        self.world.step()
        self.time += DT
        if self.world.awake_bodies() == 0:
            self.asleep_from = self.asleep_from if self.asleep_from is not None else self.time
        else:
            self.asleep_from = None

    def poses(self) -> Any:
        return self.world.poses()

    def n_contacts(self) -> int:
        return int(self.world.n_contacts())


def run(engine: str, mu: float, sleep: bool | None) -> tuple[Trajectory, float | None]:
    """One run and the time all bodies sleep from (Box2D); ``sleep`` ``None``: default.

    Box2D's worlds are built as :func:`simulate_peer` builds them (sleep on), or with
    ``sleep=False``, and stepped by the same :func:`run_peer`.
    """
    scene, steps = stack(mu), round(DURATION / DT)
    if engine not in ("BOX2D", "PYBOX2D"):
        return simulate_peer(engine, scene, DT, steps), None
    if engine == "BOX2D":
        from wuerfel_cvx.lab.peers import box2d_peer as module
    else:
        from wuerfel_cvx.lab.peers import pybox2d_peer as module  # type: ignore[no-redef]
    world = _Watched(module.build_world(scene, DT, sleep=sleep is None))
    return run_peer(engine, module.PACKAGE, scene, world, DT, steps), world.asleep_from


def main() -> None:
    """Print the Markdown table of the runs."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mu", type=float, default=0.6, help="friction coefficient")
    mu = parser.parse_args().mu
    print(f"stack-20, mu {mu:g}, dt 1/60 s, 10 s; Python {platform.python_version()}")
    print("| engine (version) | sleep | drift (m) | penetration (mm) at (s) | last 1 s (mm) "
          "| gap (mm) | toppled (s) | step (us) |")
    print("|---|---|---|---|---|---|---|---|")
    for engine in available_peers():
        variants: list[bool | None] = [None]
        if engine in ("BOX2D", "PYBOX2D"):
            variants.append(False)
        for sleep in variants:
            traj, asleep_from = run(engine, mu, sleep)
            row = measure(traj)
            label = "default" if sleep is None else "off"
            if sleep is None and engine in ("BOX2D", "PYBOX2D"):
                label = "on (default)" + ("" if asleep_from is None
                                          else f", all asleep from {asleep_from:.2f} s")
            toppled = "no" if row["toppled_s"] is None else f"{row['toppled_s']:.2f}"
            version = peer_version(engine)
            if engine == "BOX2D":
                from wuerfel_cvx.lab.peers.box2d_peer import engine_version

                version = f"box2d-python {version}, Box2D {engine_version()}"
            print(f"| {engine} ({version}) | {label} | {row['drift_m']:.3g} "
                  f"| {1e3 * row['penetration_m']:.3g} at {row['penetration_at_s']:.2f} "
                  f"| {1e3 * row['late_penetration_m']:.3g} | {1e3 * row['gap_m']:.3g} "
                  f"| {toppled} | {row['step_us']:.0f} |")


if __name__ == "__main__":
    main()
