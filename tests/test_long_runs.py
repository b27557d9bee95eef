"""Long runs: a resting stack over 10 000 steps keeps its rods and uses constant memory.

Memory is traced with :mod:`tracemalloc` from inside the run (an observer samples it).
The run necessarily grows by what the trajectory stores per step (a positions and a
velocities array, a time and a metrics row); the observer measures exactly that from the
step loop's own lists and subtracts it.  What is left (caches, compiled problems, solver
workspaces) must not grow with the number of steps.
"""

from __future__ import annotations

import gc
import sys
import tracemalloc
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from wuerfel_cvx import simulate
from wuerfel_cvx.formulations import StepQP
from wuerfel_cvx.robustness.properties import ROD_DRIFT_LIMIT
from wuerfel_cvx.solve import StepSolution

#: The step loop's lists that hold the trajectory (local names in ``simulate``).
TRAJECTORY_LISTS = ("points", "velocities", "times", "rows")

#: Growth (bytes) of the memory not held by the trajectory accepted between the first
#: sample and a later one.  The accounting of the stored trajectory is close but not
#: exact: measured on stack-10, it counts about 130 B per step more than tracemalloc
#: sees (Python reuses freed float objects, whose memory tracemalloc saw once), so the
#: untracked memory drifts down slowly and a leak smaller than that can hide.  A leak of
#: one small array per step (about 200 B with its data and shape) or more is caught: over
#: the last 7500 steps of the long run it adds about 0.5 MB.
MEMORY_GROWTH_LIMIT = 32 * 1024


def _stored_bytes(trajectory_lists: dict[str, list[Any]]) -> int:
    """Bytes the step loop's trajectory lists hold: the lists, their items, row values.

    A numpy array also holds its shape and strides (``16 ndim`` bytes, allocated
    apart from the object) and, for a view, its base array.  Values shared by every row
    (interned strings, small ints, booleans) are not counted.
    """
    objects: dict[int, object] = {}  # by id: each object counted once
    for items in trajectory_lists.values():
        objects[id(items)] = items
        for item in items:
            objects[id(item)] = item
            if isinstance(item, np.ndarray) and isinstance(item.base, np.ndarray):
                objects[id(item.base)] = item.base
            if isinstance(item, dict):
                for value in item.values():
                    if isinstance(value, float | np.floating) or (
                            isinstance(value, int) and not isinstance(value, bool)
                            and not -5 <= value <= 256):
                        objects[id(value)] = value
    return sum(sys.getsizeof(obj) + (16 * obj.ndim if isinstance(obj, np.ndarray) else 0)
               for obj in objects.values())


@dataclass
class MemorySampler:
    """An observer that records traced memory minus the trajectory at chosen steps."""

    at_steps: tuple[int, ...]
    untracked: dict[int, int]

    def __call__(self, step: int, qp: StepQP, solution: StepSolution) -> None:
        """Sample at the chosen steps (called by ``simulate`` after each step)."""
        if step not in self.at_steps:
            return
        loop = sys._getframe(1).f_locals  # the frame of simulate(), which calls us
        missing = [name for name in TRAJECTORY_LISTS if name not in loop]
        assert not missing, f"simulate() no longer keeps the lists {missing}"
        gc.collect()  # garbage awaiting the collector is not held by the run
        current, _ = tracemalloc.get_traced_memory()
        self.untracked[step] = current - _stored_bytes(
            {name: loop[name] for name in TRAJECTORY_LISTS})


def _run_with_memory_samples(scene: str, steps: int) -> tuple[float, dict[int, int]]:
    """Largest rod drift of the run and its untracked memory at 1/4, 1/2 and all steps."""
    sampler = MemorySampler((steps // 4, steps // 2, steps), {})
    tracemalloc.start()
    try:
        trajectory = simulate(scene, dt=0.01, steps=steps, observer=sampler)
    finally:
        tracemalloc.stop()
    assert trajectory.metrics["status"].isin(["optimal"]).all()
    return float(trajectory.metrics["rod_drift"].max()), sampler.untracked


def _assert_constant(untracked: dict[int, int]) -> None:
    first, *later = (untracked[step] for step in sorted(untracked))
    growth = max(later) - first
    assert growth < MEMORY_GROWTH_LIMIT, f"untracked memory by step: {untracked}"


def test_memory_held_outside_the_trajectory_stays_constant() -> None:
    drift, untracked = _run_with_memory_samples("stack-3", 800)
    assert drift < ROD_DRIFT_LIMIT
    print(f"untracked memory by step: {untracked}")
    _assert_constant(untracked)


@pytest.mark.slow
def test_ten_thousand_steps_of_a_resting_stack() -> None:
    """stack-10 for 10 000 steps (100 s): rods exact, memory constant (about 60 s)."""
    drift, untracked = _run_with_memory_samples("stack-10", 10_000)
    assert drift < ROD_DRIFT_LIMIT  # rigid position update: round-off only
    print(f"untracked memory by step: {untracked}")
    _assert_constant(untracked)
