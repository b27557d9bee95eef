"""Pictures of a trajectory: one frame, or an animation written to a GIF or an MP4.

A frame shows the squares as polygons, the tables filled, the *active contacts* (corners
within :data:`CONTACT_MARGIN` of a foreign body's edge, found by the package's own
contact search :func:`~wuerfel_cvx.contacts.find_contacts`) as dots, and the time and
step in a corner.  Axes are in metres with equal aspect, fixed over an animation.

A long trajectory is subsampled: frames are taken at ``fps`` frames per second of
simulated time (nearest stored state) and at most ``max_frames`` of them, so an
animation plays in real time unless the cap slows it.  ``.gif`` is written with Pillow;
``.mp4`` needs ``ffmpeg`` on the ``PATH``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .contacts import find_contacts
from .errors import InputError
from .geometry import FloatArray
from .model import IntArray, Model
from .scene import Scene, Square, Table

if TYPE_CHECKING:  # matplotlib is imported when a picture is drawn, not with the package
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.collections import PathCollection, PolyCollection
    from matplotlib.text import Text

    from .trajectory import Trajectory

CONTACT_MARGIN = 1e-3
"""A corner this close (m) to a foreign edge, or behind it, is drawn as touching."""

DEFAULT_FPS = 25.0
"""Frames per second of simulated time."""

DEFAULT_MAX_FRAMES = 300
"""At most this many frames per animation."""

WRITERS = {".gif": "pillow", ".mp4": "ffmpeg"}
"""Animation formats by file suffix, and the matplotlib writer of each."""


def frame_indices(times: FloatArray, fps: float = DEFAULT_FPS,
                  max_frames: int = DEFAULT_MAX_FRAMES) -> IntArray:
    """Indices of the stored states to show, ``fps`` per simulated second, at most ``max_frames``.

    ``times`` ``(N,)`` (s), ascending.  The first and last state are always shown; the
    others are the states nearest to multiples of ``1 / fps`` seconds, without repeats.
    """
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"must be a positive number of frames per second, got {fps}",
                         field="fps")
    if isinstance(max_frames, bool) or not isinstance(max_frames, int) or max_frames < 2:
        raise InputError(f"must be an integer of at least 2, got {max_frames}",
                         field="max_frames")
    times = np.asarray(times, dtype=np.float64)
    if times.size <= 1:
        return np.zeros(times.size, dtype=np.int64)
    wanted = np.arange(times[0], times[-1], 1.0 / fps)
    nearest = np.clip(np.searchsorted(times, wanted), 1, times.size - 1)
    closer_left = wanted - times[nearest - 1] <= times[nearest] - wanted
    picked = np.where(closer_left, nearest - 1, nearest)
    indices = np.unique(np.concatenate([[0], picked, [times.size - 1]])).astype(np.int64)
    if indices.size > max_frames:
        keep = np.unique(np.round(np.linspace(0, indices.size - 1, max_frames)).astype(np.int64))
        indices = indices[keep]
    return indices


def nearest_index(times: FloatArray, t: float) -> int:
    """Index of the stored state nearest to time ``t`` (s); the first one on a tie."""
    if not math.isfinite(t):
        raise InputError(f"must be a finite time in seconds, got {t}", field="t")
    return int(np.argmin(np.abs(np.asarray(times) - t)))


def trajectory_model(trajectory: Trajectory) -> Model:
    """A :class:`Model` with the trajectory's squares and tables, for the contact search.

    Squares are rebuilt from the first stored corners (centre, side, angle) and tables
    from :attr:`Trajectory.table_points`; masses are not stored and play no part in
    finding contacts, so each square gets 1 kg.
    """
    corners = trajectory.points[0].reshape(-1, 4, 2)
    squares = tuple(Square(center=_center(c), size=float(np.linalg.norm(c[1] - c[0])),
                           angle=_angle(c)) for c in corners)
    tables = []
    for c in np.asarray(trajectory.table_points).reshape(-1, 4, 2):
        tables.append(Table(center=_center(c), angle=_angle(c),
                            size=(float(np.linalg.norm(c[1] - c[0])),
                                  float(np.linalg.norm(c[2] - c[1])))))
    scene = Scene(str(trajectory.info.get("scene", "trajectory")), squares, tuple(tables),
                  allow_overlap=True)
    return Model.from_scene(scene)


def touching_points(model: Model, points: FloatArray,
                    margin: float = CONTACT_MARGIN) -> FloatArray:
    """Positions ``(C, 2)`` (m) of the corners within ``margin`` (m) of a foreign edge.

    Each corner is listed once even if it touches several edges.
    """
    # find_contacts adds the two bodies' margins: half each gives ``margin`` per pair.
    contacts = find_contacts(model, points, margin / 2.0)
    return np.asarray(model.all_points(points)[np.unique(contacts.point)], dtype=np.float64)


@dataclass
class Frame:
    """The artists of one drawn frame, updated in place by :meth:`show`."""

    axes: Axes
    squares: PolyCollection
    """One polygon per square."""
    tables: PolyCollection
    """One filled polygon per table."""
    contacts: PathCollection
    """One dot per touching corner."""
    label: Text
    """Time and step, in the upper left corner."""
    model: Model
    trajectory: Trajectory
    margin: float

    def show(self, index: int) -> None:
        """Draw stored state ``index`` (0 is the initial state)."""
        points = self.trajectory.points[index]
        self.squares.set_verts(list(points.reshape(-1, 4, 2)))
        touching = touching_points(self.model, points, self.margin)
        self.contacts.set_offsets(touching if touching.size else np.zeros((0, 2)))
        self.label.set_text(f"t = {self.trajectory.times[index]:.3f} s\nstep {index}")


def view_limits(trajectory: Trajectory, indices: IntArray) -> tuple[tuple[float, float],
                                                                     tuple[float, float]]:
    """Limits (m) of x and y that hold the squares of the shown states, with a margin."""
    shown = trajectory.points[indices].reshape(-1, 2)
    low, high = shown.min(axis=0), shown.max(axis=0)
    pad = max(0.5, 0.1 * float(np.max(high - low)))
    return (float(low[0]) - pad, float(high[0]) + pad), (float(low[1]) - pad, float(high[1]) + pad)


def draw_frame(trajectory: Trajectory, index: int, ax: Axes | None = None, *,
               indices: IntArray | None = None, margin: float = CONTACT_MARGIN,
               model: Model | None = None) -> Frame:
    """Draw stored state ``index`` on ``ax`` (a new figure if ``None``); returns its artists.

    ``indices`` are the states whose squares the view must hold (default: all).
    """
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.transforms import ScaledTranslation

    if not 0 <= index <= trajectory.n_steps:
        raise InputError(f"state {index} is outside 0..{trajectory.n_steps}", field="index")
    if ax is None:
        _, ax = plt.subplots(figsize=(6.0, 4.5))
    model = model if model is not None else trajectory_model(trajectory)
    shown = np.arange(trajectory.n_steps + 1) if indices is None else indices
    xlim, ylim = view_limits(trajectory, shown)
    tables = PolyCollection(list(np.asarray(trajectory.table_points).reshape(-1, 4, 2)),
                            facecolors="0.75", edgecolors="0.35", linewidths=0.8,
                            label="tables")
    squares = PolyCollection([], facecolors="#9ecae1", edgecolors="#08519c", linewidths=1.0,
                             label="squares")
    ax.add_collection(tables)
    ax.add_collection(squares)
    contacts = ax.scatter(np.zeros(0), np.zeros(0), s=14, color="#d62728", zorder=3,
                          label=f"contact (< {1e3 * margin:g} mm)")
    label = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", ha="left",
                    family="monospace", fontsize=9, zorder=5,  # readable over squares
                    bbox={"facecolor": "white", "alpha": 0.7, "edgecolor": "none"})
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(str(trajectory.info.get("scene", "")))
    # Below the x label: a fixed 30 points under the axes, whatever the figure's size.
    below_label = ax.transAxes + ScaledTranslation(0.0, -30 / 72, ax.figure.dpi_scale_trans)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.0), bbox_transform=below_label,
              ncol=3, fontsize=7, frameon=False, handlelength=1.2, columnspacing=1.0)
    frame = Frame(ax, squares, tables, contacts, label, model, trajectory, margin)
    frame.show(index)
    return frame


def plot(trajectory: Trajectory, t: float, ax: Axes | None = None, *,
         margin: float = CONTACT_MARGIN) -> Axes:
    """Draw the stored state nearest to time ``t`` (s); returns the Axes."""
    return draw_frame(trajectory, nearest_index(trajectory.times, t), ax, margin=margin).axes


def animation_writer(path: str | Path) -> str:
    """The matplotlib writer for ``path``'s suffix; :class:`InputError` if unusable here."""
    from matplotlib import animation as mpl_animation

    suffix = Path(path).suffix
    writer_name = WRITERS.get(suffix.lower())
    if writer_name is None:
        raise InputError(f"unsupported animation format '{suffix}' "
                         f"(use {' or '.join(WRITERS)})", source=str(path))
    if not mpl_animation.writers.is_available(writer_name):
        raise InputError(f"writing {suffix} needs {writer_name}, which is not installed "
                         "(use .gif)", source=str(path))
    return writer_name


def animate(trajectory: Trajectory, path: str | Path, *, fps: float = DEFAULT_FPS,
            max_frames: int = DEFAULT_MAX_FRAMES, dpi: float = 80.0,
            figsize: tuple[float, float] = (6.0, 4.5),
            margin: float = CONTACT_MARGIN) -> Path:
    """Write an animation to ``path`` (``.gif`` with Pillow, ``.mp4`` with ffmpeg).

    Frames are chosen by :func:`frame_indices`; playback is real time, or slower when
    ``max_frames`` caps a long run.  Returns the path.  Raises :class:`InputError` for an
    unsupported suffix, ``.mp4`` without ffmpeg, or a path that cannot be written.
    """
    import matplotlib.pyplot as plt
    from matplotlib import animation as mpl_animation

    path = Path(path)
    writer_name = animation_writer(path)
    indices = frame_indices(trajectory.times, fps, max_frames)
    span = float(trajectory.times[indices[-1]] - trajectory.times[indices[0]])
    playback_fps = fps if indices.size < 2 or span <= 0 else min(fps, (indices.size - 1) / span)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot write the animation ({exc.strerror})", source=str(path)) \
            from None
    fig, ax = plt.subplots(figsize=figsize)
    try:
        frame = draw_frame(trajectory, int(indices[0]), ax, indices=indices, margin=margin)
        fig.tight_layout()

        def update(index: int) -> list[Artist]:
            frame.show(int(index))
            return [frame.squares, frame.contacts, frame.label]

        movie = mpl_animation.FuncAnimation(fig, update, frames=[int(i) for i in indices],
                                            blit=False, repeat=False)
        # Writers take whole frames per second (a GIF stores 10 ms units anyway).
        writer = mpl_animation.writers[writer_name](fps=max(1, round(playback_fps)))
        movie.save(str(path), writer=writer, dpi=dpi)
    except OSError as exc:
        raise InputError(f"cannot write the animation ({exc.strerror or exc})",
                         source=str(path)) from None
    finally:
        plt.close(fig)
    return path


def _center(corners: FloatArray) -> tuple[float, float]:
    center = corners.mean(axis=0)
    return float(center[0]), float(center[1])


def _angle(corners: FloatArray) -> float:
    edge = corners[1] - corners[0]
    return float(math.atan2(edge[1], edge[0]))
