"""Long runs: a resting stack over 10 000 steps keeps its rods and uses constant memory.

Memory is traced with :mod:`tracemalloc` over windows of the run, opened and closed
between steps of a :class:`~wuerfel_cvx.step.simulation.Simulation`: what was allocated in a
window and is still held at its end must be what the trajectory stored in that window (a
positions and a velocities array, a time and a metrics row per step), measured from the
recorder's own lists.  Anything else (caches,
compiled problems, solver workspaces) growing with the steps shows as a surplus.  Tracing
only windows keeps the test cheap: tracemalloc makes a step about five times slower.
"""

from __future__ import annotations

import gc
import sys
import tracemalloc
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pytest

from wuerfel_cvx import Scene
from wuerfel_cvx.lab.robustness.properties import ROD_DRIFT_LIMIT
from wuerfel_cvx.step.recorder import TrajectoryRecorder
from wuerfel_cvx.step.simulation import Simulation
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

#: The recorder's lists that hold the trajectory.
TRAJECTORY_LISTS = ("points", "velocities", "times", "rows")

#: Window length (steps) and the surplus (bytes) accepted at its end.  The accounting of
#: the stored trajectory is close but not exact: it counts about 100 B per step more than
#: tracemalloc sees (measured surplus -98 kB and -101 kB over the two windows; most likely
#: Python's reuse of freed float objects, whose memory tracemalloc saw once), so a leak
#: smaller than that can hide.  One leaked small array per step (about 190 B with its
#: data and shape) leaves a surplus of 79 kB after 1000 steps (measured, test below).
WINDOW = 1000
SURPLUS_LIMIT = 32 * 1024


def _stored_bytes(trajectory_lists: dict[str, list[Any]]) -> int:
    """Bytes the step loop's trajectory lists hold: the lists, their items, row values.

    A numpy array also holds its shape and strides (``16 ndim`` bytes, allocated
    apart from the object) and, for a view, its base array.  Values shared by every row
    (interned strings, small ints, booleans) are not counted, nor a row value whose memory
    tracemalloc did not see allocated (a float object reused from Python's free list: no
    new memory).  Called while tracing.
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
                    if (isinstance(value, float | np.floating) or (
                            isinstance(value, int) and not isinstance(value, bool)
                            and not -5 <= value <= 256)) \
                            and tracemalloc.get_object_traceback(value) is not None:
                        objects[id(value)] = value
    return sum(sys.getsizeof(obj) + (16 * obj.ndim if isinstance(obj, np.ndarray) else 0)
               for obj in objects.values())


@dataclass
class WindowSampler:
    """An observer that traces memory over windows ``[start, start + WINDOW]`` of steps.

    ``surplus[start]`` is the memory allocated in the window and still held at its end
    minus what the trajectory lists gained in it (bytes).
    """

    starts: tuple[int, ...]
    surplus: dict[int, int] = field(default_factory=dict)
    _open: tuple[int, dict[str, int], set[int]] | None = None

    def __call__(self, step: int, recorder: TrajectoryRecorder) -> None:
        """Open or close a window (called after each step with the run's recorder)."""
        if step not in self.starts and (self._open is None or step != self._open[0] + WINDOW):
            return
        lists: dict[str, list[Any]] = {name: getattr(recorder, name)
                                       for name in TRAJECTORY_LISTS}
        gc.collect()  # garbage awaiting the collector is not held by the run
        if self._open is None:
            held_before = {id(item) for items in lists.values() for item in items}
            self._open = (step, {name: sys.getsizeof(items) for name, items in lists.items()},
                          held_before)
            tracemalloc.start()
            return
        traced, _ = tracemalloc.get_traced_memory()
        start, capacity_before, held_before = self._open
        self._open = None
        new_items = {name: [item for item in items if id(item) not in held_before]
                     for name, items in lists.items()}
        stored = _stored_bytes(new_items) - sum(sys.getsizeof(items) for items in
                                                 new_items.values())
        tracemalloc.stop()
        for name, items in lists.items():  # a list that grew got a new, traced buffer
            if sys.getsizeof(items) != capacity_before[name]:
                stored += sys.getsizeof(items) - sys.getsizeof([])
        self.surplus[start] = traced - stored


def run_sampled(scene: str, steps: int, sampler: WindowSampler,
                leaked: list[np.ndarray] | None = None) -> Trajectory:
    """Step ``scene`` (dt 0.01 s), calling ``sampler`` after each step.

    With ``leaked``, one small extra array per step is kept in it: a leak to be found.
    """
    simulation = Simulation(Scene.named(scene), dt=0.01)
    for _ in range(steps):
        record = simulation.step()
        if leaked is not None:
            leaked.append(np.zeros(8))  # 64 B of data, about 200 B in all
        sampler(record.step, simulation.recorder)
    return simulation.trajectory()


@pytest.mark.slow
def test_ten_thousand_steps_of_a_resting_stack() -> None:
    """stack-5 for 10 000 steps (100 s): rods exact, memory constant.

    Traced over steps 1000-2000 and 9000-10000: about 30 s of computing in all.
    """
    sampler = WindowSampler(starts=(1000, 9000))
    trajectory = run_sampled("stack-5", 10_000, sampler)
    assert (trajectory.metrics["status"] == "optimal").all()
    assert trajectory.metrics["rod_drift"].max() < ROD_DRIFT_LIMIT  # rigid update: round-off
    print(f"memory surplus by window start: {sampler.surplus}")
    assert set(sampler.surplus) == {1000, 9000}
    assert max(sampler.surplus.values()) < SURPLUS_LIMIT, sampler.surplus
    # and the accounting itself is sound: its float overcount is under 200 B per step
    assert min(sampler.surplus.values()) > -200 * WINDOW, sampler.surplus


def test_a_leak_of_one_small_array_per_step_is_caught() -> None:
    """The window check can fail: a run that keeps one extra small array per step."""
    sampler = WindowSampler(starts=(100,))
    leaked: list[np.ndarray] = []
    run_sampled("stack-3", 100 + WINDOW, sampler, leaked)
    print(f"memory surplus with a leak: {sampler.surplus}")
    assert sampler.surplus[100] > SURPLUS_LIMIT, sampler.surplus
