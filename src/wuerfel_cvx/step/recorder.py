"""Recording a run: states, one metrics row per step, and the run's settings.

Shared by the package's own simulation loop (:mod:`wuerfel_cvx.step.simulation`) and the peer
engines (:mod:`wuerfel_cvx.lab.peers`), so that both write the same columns, computed by the
same functions of :mod:`wuerfel_cvx.step.metrics`, and the same ``info``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from pandas.api.types import pandas_dtype

from ..formulations import Formulation, get_formulation
from ..scenes.geometry import FloatArray
from ..scenes.scene import Scene
from ..settings import SETTING_NAMES, Settings
from ..solve.paths import PATH_COUNTS
from ..trajectory import NULLABLE_COLUMNS, Trajectory
from ..versions import package_version
from .metrics import state_metrics
from .model import Model, State

METRIC_COLUMNS = (
    "step", "time_s", "solver", "status", "primary_status", "verified", "n_variables",
    "n_equalities",
    "n_inequalities", "n_contacts", "search_time_s", "build_time_s", "solve_time_s",
    "update_time_s", "record_time_s", "step_time_s", "solver_time_s", "polish_time_s",
    "iterations", "primal_residual", "dual_residual", "complementarity", "rod_drift",
    "penetration_m", "kinetic_energy_J", "potential_energy_J", "total_energy_J", "path",
    "passes", "polish", "signorini_violation_Nsm", "push_at_distance_Ns",
    "push_gap_product_Nsm", "coulomb_violation_Ns", "dissipation_violation_J",
    "friction_work_J",
    "coulomb_iterations", "coulomb_converged",
)
"""Columns of :attr:`Trajectory.metrics`, one row per step (state after the step).

The times (s) split the step's wall time into the stages it runs
(:data:`~wuerfel_cvx.step.simulation.STAGES`), which add up to ``step_time_s``:
``search_time_s`` the contact search of the state the step starts from (run when that state
was reached), ``build_time_s`` building the QPs (islands, rows, the further passes'
QPs), ``solve_time_s`` the solve calls, ``update_time_s`` advancing the bodies, the
physical check and merging the islands, ``record_time_s`` the row's metrics and the
recording.  Within ``solve_time_s``, ``solver_time_s`` is the solver's own reported time and
``polish_time_s`` the time after the solver returned (mapping back, the polish and the KKT
check).  ``solver`` and ``status`` are those of the solver that produced the
step; ``primary_status`` is the run's own solver's status on it, which differs only when
that solver failed and a ``fallback`` solver took over.  ``path`` is how the step's QPs
reached the solver: ``native``, ``compiled`` or ``declared``
(:class:`~wuerfel_cvx.solve.paths.SolvePath`; joined by ``+`` when a step's QPs went different
ways; ``reused`` for a QP answered on its structure's last active set, no solver called;
``none`` when no QP was solved, ``peer`` for a peer engine).  ``passes`` is the
number of QPs solved one after another for the step (the most of any island): 1 for a
single-pass formulation, up to ``max_passes`` for the
closest-approach Gauss-Newton passes of ``velocity``, 0 for a step that solved none; its
times and ``iterations`` are those passes' sums.  ``polish`` is what became of the step's
answers (:data:`~wuerfel_cvx.solve.kkt.POLISH_OUTCOMES`: ``polished``, ``exact`` where
the solver's answers needed no polish, ``reused``, ``kept`` with polishing off,
``rejected (reason)`` if any QP's polish was, with the reasons of
:attr:`wuerfel_cvx.solve.kkt.Polish.reason`).  The next six are the physical
criteria of the step's contact impulses (:mod:`wuerfel_cvx.step.criteria`: Signorini and
pushes at a distance in every step with a contact, the friction criteria NaN for a step
without friction); a step whose rows push at a distance beyond the bound derived from the
tolerance is not ``verified``.  ``coulomb_iterations`` and ``coulomb_converged`` are the
Coulomb fixed point's (:data:`~wuerfel_cvx.friction.coulomb.COULOMB_COLUMNS`; empty without it).
"""


def run_info(scene: Scene, settings: Settings, *, formulation: Formulation | None = None,
             steps: int = 0, packages: dict[str, str] | None = None) -> dict[str, Any]:
    """A run's ``info``: its scene (name and data), its settings and the versions.

    ``formulation``: the run's formulation object, when it differs from the settings' (a
    friction model set); ``packages`` maps a key of ``info["versions"]`` to a
    distribution whose version it records (``wuerfel_cvx`` is always recorded).
    ``friction_model`` is ``None`` for a formulation without friction.
    """
    formulation = get_formulation(settings.formulation) if formulation is None else formulation
    friction = formulation.friction
    return info_of(scene, {**settings.to_dict(), "formulation": formulation.name,
                           "steps": int(steps),
                           "friction_model": None if friction is None
                           else friction.friction_model}, packages)


def info_of(scene: Scene, fields: dict[str, Any],
            packages: dict[str, str] | None = None) -> dict[str, Any]:
    """A trajectory's ``info``: the scene (name and data), ``fields`` and the versions.

    ``packages`` maps a key of ``info["versions"]`` to a distribution whose version it
    records (``wuerfel_cvx`` is always recorded).  A peer engine's run
    (:mod:`wuerfel_cvx.lab.peers`) gives its own ``fields``; every run's ``info`` has the same
    keys (the settings, ``steps``, ``friction_model`` and the solve path's counts), ``None``
    where a run has no such value.
    """
    standard = dict.fromkeys((*SETTING_NAMES, "steps", "friction_model", *PATH_COUNTS))
    return {"scene": scene.name, "scene_data": scene.to_dict(), **standard, **fields,
            "versions": {key: package_version(package) for key, package in
                         {"wuerfel_cvx": "wuerfel_cvx", **(packages or {})}.items()}}


@dataclass
class TrajectoryRecorder:
    """States and metrics rows of a run as it goes; :meth:`trajectory` at any point."""

    model: Model
    info: dict[str, Any]
    column_dtypes: dict[str, str] = field(default_factory=dict)
    """Dtypes for columns a recorder's rows may leave empty (``pd.NA``), e.g. a peer's."""
    times: list[float] = field(default_factory=list)
    points: list[FloatArray] = field(default_factory=list)
    velocities: list[FloatArray] = field(default_factory=list)
    rows: list[dict[str, Any]] = field(default_factory=list)

    @classmethod
    def start(cls, model: Model, info: dict[str, Any], state: State,
              column_dtypes: dict[str, str] | None = None) -> TrajectoryRecorder:
        """A recorder holding the initial ``state`` at time 0."""
        recorder = cls(model, info, dict(column_dtypes or {}))
        recorder.times.append(0.0)
        recorder.points.append(state.points)
        recorder.velocities.append(state.velocities)
        return recorder

    def record(self, time: float, state: State, row: dict[str, Any]) -> None:
        """Append the state at ``time`` (s) after a step, and that step's metrics ``row``.

        The row's :data:`~wuerfel_cvx.step.metrics.STATE_COLUMNS` (the rod drift and the
        energies, functions of the state alone) are left to :meth:`trajectory`, which
        computes them for every state at once.
        """
        self.times.append(time)
        self.points.append(state.points)
        self.velocities.append(state.velocities)
        self.rows.append(row)

    def trajectory(self) -> Trajectory:
        """The trajectory recorded so far (a copy of the lists' current contents).

        Whole steps only: a state whose row a Ctrl-C kept from being recorded is left out.
        """
        states = len(self.rows) + 1
        points = np.array(self.points[:states])
        velocities = np.array(self.velocities[:states])
        metrics = pd.DataFrame(self.rows, columns=list(METRIC_COLUMNS))
        if self.rows:  # each step's row: the state after it
            for column, values in state_metrics(self.model, points[1:], velocities[1:]).items():
                metrics[column] = values
        for column, dtype in {**NULLABLE_COLUMNS, **self.column_dtypes}.items():
            # column by column: the frame's astype copies every column
            metrics[column] = metrics[column].astype(pandas_dtype(dtype))
        return Trajectory(times=np.array(self.times[:states]), points=points,
                          velocities=velocities, metrics=metrics,
                          table_points=self.model.table_points.copy(), info=dict(self.info))
