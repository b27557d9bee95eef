"""A simulated trajectory: states over time, per-step metrics, saving and loading."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from .scenes.geometry import FloatArray

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from .gradients.tape import GradientTape
    from .scenes.scene import Scene
    from .step.model import Model

NULLABLE_COLUMNS = {"coulomb_iterations": "Int64", "coulomb_converged": "boolean"}
"""Metrics columns that may be empty (``NA``), with their dtypes: the Coulomb fixed point's
(:data:`wuerfel_cvx.friction.coulomb.COULOMB_COLUMNS`), empty in runs without it; kept by
:meth:`Trajectory.load`."""


@dataclass
class Trajectory:
    """States at ``steps + 1`` instants and one metrics row per step.

    ``points`` and ``velocities`` are ``(steps + 1, 4 n, 2)`` (m and m/s): square ``i``'s
    corners at rows ``4i..4i+3``, counter-clockwise.  ``times`` is ``(steps + 1,)`` (s).
    A trajectory cut short by a failed step holds the steps that succeeded.
    """

    times: FloatArray
    points: FloatArray
    velocities: FloatArray
    metrics: pd.DataFrame
    table_points: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    """Fixed table corners ``(4 t, 2)`` (m)."""
    info: dict[str, Any] = field(default_factory=dict)
    """Run settings: scene name, formulation, solver, tolerance, dt, package versions, and
    the scene itself (``scene_data``, the TOML schema of :meth:`Scene.to_dict`) with the
    model options (``table_mass``, ``extra_rod``)."""
    tape: GradientTape | None = field(default=None, repr=False, compare=False)
    """What a gradient through the run needs (a run with ``gradients=True``); ``None``
    otherwise, and for a loaded trajectory (:meth:`save` does not keep it)."""

    @property
    def scene(self) -> Scene | None:
        """The simulated scene, rebuilt from ``info["scene_data"]``; ``None`` if not recorded.

        It is the very scene that was run: :meth:`Scene.from_dict` of its
        :meth:`Scene.to_dict`, which survives :meth:`save` and :meth:`load`.
        """
        data = self.info.get("scene_data")
        if data is None:
            return None
        from .scenes.scene import Scene

        return Scene.from_dict(data, source=str(self.info.get("scene", "<trajectory>")))

    def model(self) -> Model | None:
        """The run's model: :attr:`scene` with the recorded model options (or ``None``)."""
        scene = self.scene
        if scene is None:
            return None
        from .step.model import Model

        return Model.from_scene(scene, table_mass=self.info.get("table_mass"),
                                extra_rod=bool(self.info.get("extra_rod", False)))

    @property
    def n_steps(self) -> int:
        """Number of completed steps."""
        return int(self.times.shape[0]) - 1

    @staticmethod
    def npz_path(path: str | Path) -> Path:
        """Where :meth:`save` writes for ``path``: it, with ``.npz`` appended if absent."""
        path = Path(path)
        return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")

    @staticmethod
    def metrics_path(path: str | Path) -> Path:
        """Where :meth:`save` puts the metrics CSV for a given ``.npz`` path."""
        path = Path(path)
        return path.with_name(path.stem + ".metrics.csv")

    def save(self, path: str | Path) -> Path:
        """Write ``times``, ``points``, ``velocities`` (and tables, settings) to a ``.npz``.

        The metrics go to ``<stem>.metrics.csv`` beside it.  Returns the ``.npz`` path.
        """
        path = self.npz_path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, times=self.times, points=self.points, velocities=self.velocities,
                 table_points=self.table_points, info=np.array(json.dumps(self.info)))
        self.metrics.to_csv(self.metrics_path(path), index=False)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Trajectory:
        """Read a trajectory written by :meth:`save` (no pickles are loaded)."""
        path = Path(path)
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
        metrics_file = cls.metrics_path(path)
        metrics = pd.read_csv(metrics_file) if metrics_file.exists() else pd.DataFrame()
        metrics = metrics.astype({name: dtype for name, dtype in NULLABLE_COLUMNS.items()
                                  if name in metrics.columns})
        return cls(times=arrays["times"], points=arrays["points"],
                   velocities=arrays["velocities"], metrics=metrics,
                   table_points=arrays.get("table_points", np.zeros((0, 2))),
                   info=json.loads(str(arrays["info"])) if "info" in arrays else {})

    def gradient(self, dloss_dpoints: FloatArray,
                 wrt: str | tuple[str, ...] | list[str]) -> dict[str, FloatArray]:
        """The gradient of a loss of the recorded corners with respect to the run's inputs.

        ``dloss_dpoints`` is shaped like :attr:`points` ``(steps + 1, 4 n, 2)``: the loss's
        derivative with respect to every recorded corner position (zeros where the loss does
        not look).  ``wrt`` is a name or names of ``center`` ``(n, 2)`` (m), ``angle``
        ``(n,)`` (rad), ``velocity`` ``(n, 2)`` (m/s), ``angular_velocity`` ``(n,)``
        (rad/s), ``friction`` ``(n,)`` (1), ``mass`` ``(n,)`` (kg), per moving body (squares
        first, then boxes, as in the scene), and ``gravity`` ``(2,)`` (m/s^2); the initial
        state's and the scene's values.  A body's ``friction`` is its own coefficient: a
        contact's is ``sqrt(mu_a mu_b)``, so on a table of the same coefficient the
        contact's derivative is twice the body's.

        Returns a dict with an array per requested name and, on where the derivative is
        one-sided: ``flagged_steps`` (1-based steps with a weakly active row, where the
        active set may change nearby, or whose polish was rejected), ``weak_rows`` (their
        counts) and ``crossings`` (how many steps were flagged).  Each step's active set is
        that of its polished answer: the derivative from the side the run took.  The method
        is :mod:`wuerfel_cvx.gradients` (backpropagation through each step's reduced KKT
        system), which says what it covers.

        Raises :class:`~wuerfel_cvx.gradients.GradientError` (an ``InputError``) for a run
        recorded without ``gradients=True``, a step that was not verified, a bad shape or
        an unknown name.
        """
        from .gradients import gradient

        return gradient(self, self.tape, dloss_dpoints, wrt)

    def plot(self, t: float, ax: Axes | None = None) -> Axes:
        """Draw the stored state nearest to time ``t`` (s) (:func:`wuerfel_cvx.animation.plot`).

        Squares as polygons, tables filled, touching corners marked; returns the Axes.
        """
        from .animation import plot

        return plot(self, t, ax)

    def animate(self, path: str | Path, *, fps: float = 25.0, max_frames: int = 300,
                dpi: float = 80.0, figsize: tuple[float, float] = (6.0, 4.5),
                progress: bool = False) -> Path:
        """Write an animation: ``.gif`` (Pillow) or ``.mp4`` (needs ffmpeg); returns the path.

        ``fps`` frames per simulated second, at most ``max_frames`` frames
        (:func:`wuerfel_cvx.animation.animate`); ``progress`` shows a bar of the frames.
        """
        from .animation import animate

        return animate(self, path, fps=fps, max_frames=max_frames, dpi=dpi, figsize=figsize,
                       progress=progress)

    def _bodies(self) -> str:
        """The moving bodies as the scene has them: squares and boxes."""
        scene = self.scene
        if scene is None:  # a trajectory saved without its scene
            return _count(self.points.shape[1] // 4, "body", "bodies")
        return _bodies_text(len(scene.squares), len(scene.boxes))

    def summary(self) -> str:
        """A few lines on the run: duration, extremes of the metrics, timing."""
        m = self.metrics
        lines = [
            f"scene {self.info.get('scene', '?')}: {self._bodies()}, "
            f"{self.n_steps} steps of {self.info.get('dt', float('nan')):g} s "
            f"({self.times[-1]:g} s simulated)",
            f"formulation {self.info.get('formulation')}, solver {self.info.get('solver')}, "
            f"tol {self.info.get('tol')}",
        ]
        if len(m):
            energy = m["total_energy_J"].to_numpy()
            solved = m[m["status"] != "asleep"]
            asleep = len(m) - len(solved)
            slept = f" ({asleep} more asleep: no QP)" if asleep else ""
            lines += [
                f"max rod drift        {m['rod_drift'].max():.3e} (relative)",
                f"max penetration      {m['penetration_m'].max():.3e} m",
                f"energy               {energy[0]:.6g} J -> {energy[-1]:.6g} J "
                f"(largest one-step rise {np.max(np.diff(energy, prepend=energy[0])):.3e} J)",
                f"verified steps       {int(solved['verified'].sum())}/{len(solved)}{slept}",
                *_time_lines(solved),
            ]
            lines += _friction_lines(self.info, m) + _coulomb_lines(m)
        return "\n".join(lines)


def _time_lines(solved: pd.DataFrame) -> list[str]:
    """Where a step's time went: each stage's median time per step (ms), the solver's own.

    Medians, so that the first steps' one-off work (numba loading compiled code) does not
    hide a typical step; they need not add up to the median step.  A run recorded before
    the stages were (no ``search_time_s``) shows its build and solve medians.
    """
    if "search_time_s" not in solved.columns:
        return [f"median build / solve {1e3 * solved['build_time_s'].median():.2f} ms / "
                f"{1e3 * solved['solve_time_s'].median():.2f} ms per step"]
    stages = ("search", "build", "solve", "update", "record")
    medians = {stage: 1e3 * float(solved[f"{stage}_time_s"].median()) for stage in stages}
    return [f"median step          {1e3 * float(solved['step_time_s'].median()):.3f} ms: "
            + ", ".join(f"{stage} {medians[stage]:.3f}" for stage in stages),
            f"solver's own         {1e3 * float(solved['solver_time_s'].median()):.3f} ms "
            f"(median, within solve; polish and check "
            f"{1e3 * float(solved['polish_time_s'].median()):.3f} ms)"]


def _bodies_text(squares: int, boxes: int) -> str:
    """``"1 square"``, ``"2 squares and 1 box"``, ``"3 boxes"``."""
    parts = [_count(squares, "square", "squares")] if squares else []
    if boxes or not squares:
        parts.append(_count(boxes, "box", "boxes"))
    return " and ".join(parts)


def _friction_lines(info: dict[str, Any], metrics: pd.DataFrame) -> list[str]:
    """The summary's lines on the contact criteria: pushes at a distance, and friction's.

    The push line when any step had a contact; the friction line when any step had a
    contact with friction.
    """
    lines = []
    pushes = ("signorini_violation_Nsm", "push_gap_product_Nsm")
    if set(pushes) <= set(metrics.columns) and not metrics[list(pushes)].isna().all().all():
        worst = metrics[list(pushes)].max()
        outcomes = metrics["polish"].astype("string").value_counts() if "polish" in metrics \
            else pd.Series(dtype=int)
        polish = ", ".join(f"{count} {outcome}" for outcome, count in outcomes.items()
                           if outcome != "asleep" and outcome)
        lines.append(f"pushes at a distance Signorini gap x impulse {worst.iloc[0]:.2e} N s m, "
                     f"rows {worst.iloc[1]:.2e} N s m; answers: {polish or 'none'}")
    columns = ("coulomb_violation_Ns", "dissipation_violation_J")
    if set(columns) <= set(metrics.columns) and not metrics[list(columns)].isna().all().all():
        worst = metrics[list(columns)].max()
        lines.append(f"friction ({info.get('friction_model')}): largest Coulomb excess "
                     f"{worst.iloc[0]:.2e} N s, dissipation gap {worst.iloc[1]:.2e} J")
    return lines


def _coulomb_lines(metrics: pd.DataFrame) -> list[str]:
    """The Coulomb fixed point's line of :meth:`Trajectory.summary` (none without it).

    Names the steps whose fixed point did not converge (the first ten).
    """
    if "coulomb_converged" not in metrics or metrics["coulomb_converged"].isna().all():
        return []
    ran = metrics[metrics["coulomb_converged"].notna()]
    failed = ran.loc[~ran["coulomb_converged"].astype(bool), "step"].tolist()
    line = (f"coulomb fixed point  converged in {len(ran) - len(failed)}/{len(ran)} steps "
            f"(at most {int(ran['coulomb_iterations'].max())} iterations)")
    if failed:
        shown = ", ".join(str(step) for step in failed[:10])
        line += f"; not converged: steps {shown}" + (" ..." if len(failed) > 10 else "")
    return [line]


def _count(number: int, noun: str, plural: str) -> str:
    """``"1 box"``, ``"3 boxes"``."""
    return f"{number} {noun if number == 1 else plural}"
