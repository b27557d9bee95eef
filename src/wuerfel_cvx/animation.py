"""Pictures of a trajectory: one frame, or an animation written to a GIF or an MP4.

A frame shows the moving bodies as polygons, the tables filled, the *active contacts*
(corners within :data:`CONTACT_MARGIN` of a foreign body's edge, found by the package's
own contact search :func:`~wuerfel_cvx.step.contacts.find_contacts`) as dots, and the time and
step in a band above the axes.  Axes are in metres with equal aspect, fixed over an
animation, and frame the bodies with a margin and the tables near them, cropping a table
much larger than the bodies (:func:`view_limits`).

A long trajectory is subsampled: frames are taken at ``fps`` frames per second of
simulated time (nearest stored state) and at most ``max_frames`` of them, so an
animation plays in real time unless the cap slows it.  ``.gif`` is written with Pillow
from blitted frames (:func:`blitted_frames`); ``.mp4`` needs ``ffmpeg`` on the ``PATH``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import InputError
from .scenes.geometry import FloatArray
from .scenes.scene import Scene
from .step.contacts import find_contacts
from .step.model import IntArray, Model

if TYPE_CHECKING:  # matplotlib is imported when a picture is drawn, not with the package
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.collections import PathCollection, PolyCollection
    from matplotlib.figure import Figure
    from matplotlib.text import Text
    from PIL.Image import Image

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
    check_frame_rate(fps)
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
    """The trajectory's :class:`Model`, for the contact search of the frames.

    :meth:`Trajectory.model` rebuilds the very scene that was run from
    ``info["scene_data"]``; a trajectory without it (a file written before scenes were
    recorded) gets :func:`model_from_corners`.
    """
    model = trajectory.model()
    return model if model is not None else model_from_corners(trajectory)


def model_from_corners(trajectory: Trajectory) -> Model:
    """A :class:`Model` rebuilt from the first stored corners and the table corners.

    Each body's centre and angle come from its corners; its width from side 0-1 and its
    height from side 1-2 (m), so boxes of any width x height are rebuilt (through the
    ``[[boxes]]`` schema when some body is not square).  Masses are not stored and play
    no part in finding contacts, so each body gets 1 kg.
    """
    corners = np.asarray(trajectory.points[0]).reshape(-1, 4, 2)
    bodies = [_body_of(c) for c in corners]
    tables = [_body_of(c) for c in np.asarray(trajectory.table_points).reshape(-1, 4, 2)]
    square = all(math.isclose(w, h, rel_tol=SQUARE_TOLERANCE) for _, (w, h), _ in bodies)
    data: dict[str, object] = {
        "name": str(trajectory.info.get("scene", "trajectory")), "allow_overlap": True,
        "tables": [{"center": list(c), "size": list(s), "angle": a} for c, s, a in tables],
        "squares" if square else "boxes": [
            {"center": list(c), "size": s[0] if square else list(s), "angle": a}
            for c, s, a in bodies]}
    return Model.from_scene(Scene.from_dict(data, source="<trajectory corners>"))


SQUARE_TOLERANCE = 1e-9
"""Relative difference of two side lengths below which a rebuilt body is a square."""


def _body_of(corners: FloatArray) -> tuple[tuple[float, float], tuple[float, float], float]:
    """Centre (m), (width, height) (m) and angle (rad) of four counter-clockwise corners."""
    center = corners.mean(axis=0)
    edge = corners[1] - corners[0]
    size = (float(np.linalg.norm(edge)), float(np.linalg.norm(corners[2] - corners[1])))
    return (float(center[0]), float(center[1])), size, float(math.atan2(edge[1], edge[0]))


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
    """One polygon per moving body."""
    tables: PolyCollection
    """One filled polygon per table."""
    contacts: PathCollection
    """One dot per touching corner."""
    label: Text
    """Time and step, in a band above the axes (never over a body)."""
    model: Model
    trajectory: Trajectory
    margin: float

    @property
    def moving(self) -> tuple[Artist, ...]:
        """The artists that :meth:`show` changes."""
        return (self.squares, self.contacts, self.label)

    def show(self, index: int) -> None:
        """Draw stored state ``index`` (0 is the initial state)."""
        points = self.trajectory.points[index]
        self.squares.set_verts(list(points.reshape(-1, 4, 2)))
        touching = touching_points(self.model, points, self.margin)
        self.contacts.set_offsets(touching if touching.size else np.zeros((0, 2)))
        self.label.set_text(f"t = {self.trajectory.times[index]:.3f} s   step {index}")


LONG_TABLE = 1.0
"""Along x (or y), a table whose part outside the bodies' view (their extent and margin)
is longer than this many times that view is cropped there: a 40 m floor under a 1 m
square, or the card house's ground, 4 m deep under a 1.8 m house.  The view then holds
the bodies, with the table's part next to them, and reaches the table's nearest end if
it lies wholly beside them."""

Limits = tuple[tuple[float, float], tuple[float, float]]


def view_limits(trajectory: Trajectory, indices: IntArray) -> Limits:
    """Limits (m) of x and y that hold the bodies of the shown states and the tables near them.

    The bodies of every state in ``indices`` are inside with a margin (at least 0.5 m), and
    every table with a fifth of it, except along an axis where the table's part outside
    the bodies' view is longer than :data:`LONG_TABLE` times that view: there the view
    holds the bodies with their margin (which shows the table next to them), and reaches
    the table's nearest end if it lies wholly beside them.
    """
    bodies = np.asarray(trajectory.points)[indices].reshape(-1, 2)
    tables = np.asarray(trajectory.table_points, dtype=np.float64).reshape(-1, 4, 2)
    if bodies.size == 0 and tables.size == 0:
        return (-1.0, 1.0), (-1.0, 1.0)
    t_low, t_high = tables.min(axis=1), tables.max(axis=1)  # (tables, 2) each
    if bodies.size:
        low, high = bodies.min(axis=0), bodies.max(axis=0)
    else:
        low, high = t_low.min(axis=0), t_high.max(axis=0)
    pad = max(0.5, 0.1 * float(np.max(high - low)))
    low, high = low - pad, high + pad  # the bodies' view
    inside = np.clip(np.minimum(t_high, high) - np.maximum(t_low, low), 0.0, None)
    whole = (t_high - t_low) - inside <= LONG_TABLE * (high - low)  # (tables, 2)
    # A table held whole gets a fifth of the margin: a floor's underside needs no air.
    low_all = np.min(np.vstack([low, np.where(whole, t_low - pad / 5, np.inf)]), axis=0)
    high_all = np.max(np.vstack([high, np.where(whole, t_high + pad / 5, -np.inf)]), axis=0)
    # A cropped table wholly beside that view: the view reaches its nearest end.
    low_all = np.min(np.vstack([low_all, np.clip(low, t_low, t_high)]), axis=0)
    high_all = np.max(np.vstack([high_all, np.clip(high, t_low, t_high)]), axis=0)
    return (float(low_all[0]), float(high_all[0])), (float(low_all[1]), float(high_all[1]))


def draw_frame(trajectory: Trajectory, index: int, ax: Axes | None = None, *,
               indices: IntArray | None = None, margin: float = CONTACT_MARGIN,
               model: Model | None = None) -> Frame:
    """Draw stored state ``index`` on ``ax`` (a new figure if ``None``); returns its artists.

    ``indices`` are the states whose bodies the view must hold (default: all).
    """
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection
    from matplotlib.transforms import ScaledTranslation

    if not 0 <= index <= trajectory.n_steps:
        raise InputError(f"state {index} is outside 0..{trajectory.n_steps}", field="index")
    if ax is None:  # constrained: the legend below the x label stays in the figure
        _, ax = plt.subplots(figsize=(6.0, 4.5), layout="constrained")
    model = model if model is not None else trajectory_model(trajectory)
    shown = np.arange(trajectory.n_steps + 1) if indices is None else indices
    xlim, ylim = view_limits(trajectory, shown)
    tables = PolyCollection(list(np.asarray(trajectory.table_points).reshape(-1, 4, 2)),
                            facecolors="0.75", edgecolors="0.35", linewidths=0.8,
                            label="tables")
    squares = PolyCollection([], facecolors="#9ecae1", edgecolors="#08519c", linewidths=1.0,
                             label="bodies")
    ax.add_collection(tables)
    ax.add_collection(squares)
    contacts = ax.scatter(np.zeros(0), np.zeros(0), s=14, color="#d62728", zorder=3,
                          label=f"contact (< {1e3 * margin:g} mm)")
    points = ax.figure.dpi_scale_trans
    # The time label sits in a band between the axes and the title, outside the axes.
    label = ax.text(0.5, 1.0, "", transform=ax.transAxes + ScaledTranslation(0, 3 / 72, points),
                    va="bottom", ha="center", family="monospace", fontsize=9)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(str(trajectory.info.get("scene", "")), pad=17)
    # Below the x label: a fixed 30 points under the axes, whatever the figure's size.
    below_label = ax.transAxes + ScaledTranslation(0.0, -30 / 72, points)
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


def check_frame_rate(fps: float, field: str = "fps") -> float:
    """``fps`` if it is a positive finite number of frames per second, else InputError."""
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"must be a positive number of frames per second, got {fps}",
                         field=field)
    return fps


def animate(trajectory: Trajectory, path: str | Path, *, fps: float = DEFAULT_FPS,
            max_frames: int = DEFAULT_MAX_FRAMES, dpi: float = 80.0,
            figsize: tuple[float, float] = (6.0, 4.5),
            margin: float = CONTACT_MARGIN, progress: bool = False) -> Path:
    """Write an animation to ``path`` (``.gif`` with Pillow, ``.mp4`` with ffmpeg).

    Frames are chosen by :func:`frame_indices`; playback is real time, or slower when
    ``max_frames`` caps a long run.  ``progress`` shows a bar of the frames on standard
    error.  Returns the path.  Raises :class:`InputError` for an unsupported suffix,
    ``.mp4`` without ffmpeg, or a path that cannot be written.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from tqdm.auto import tqdm

    path = Path(path)
    writer_name = animation_writer(path)
    indices = frame_indices(trajectory.times, fps, max_frames)
    span = float(trajectory.times[indices[-1]] - trajectory.times[indices[0]])
    playback_fps = fps if indices.size < 2 or span <= 0 else min(fps, (indices.size - 1) / span)
    # Writers take whole frames per second (a GIF stores 10 ms units anyway).
    whole_fps = max(1, round(playback_fps))
    figure = Figure(figsize=figsize, dpi=dpi)
    FigureCanvasAgg(figure)
    frame = draw_frame(trajectory, int(indices[0]), figure.subplots(), indices=indices,
                       margin=margin)
    figure.tight_layout()
    shown = tqdm([int(i) for i in indices], disable=not progress, unit="frame",
                 desc=path.name, leave=False)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if writer_name == "pillow":
            _write_gif(figure, frame, shown, path, whole_fps)
        else:
            _write_movie(figure, frame, shown, path, writer_name, whole_fps, dpi)
    except OSError as exc:
        raise InputError(f"cannot write the animation ({exc.strerror or exc})",
                         source=str(path)) from None
    return path


def _write_gif(figure: Figure, frame: Frame, indices: Iterable[int], path: Path,
               fps: int) -> None:
    """Write a looping GIF of ``1000 / fps`` ms frames from :func:`blitted_frames`.

    The settings of matplotlib's Pillow writer, from frames drawn in a fraction of the time.
    """
    images = list(blitted_frames(figure, frame, indices))
    images[0].save(path, save_all=True, append_images=images[1:], duration=int(1000 / fps),
                   loop=0)


def blitted_frames(figure: Figure, frame: Frame, indices: Iterable[int]) -> Iterator[Image]:
    """RGBA images of ``frame`` at each state of ``indices``, as full redraws would look.

    The still parts (axes, ticks, tables, legend, title) are drawn once; per frame only
    :attr:`Frame.moving` is drawn over a copy of them (blitting).
    """
    from PIL import Image as PILImage

    canvas = figure.canvas
    for artist in frame.moving:
        artist.set_animated(True)  # left out of the full draw below
    try:
        canvas.draw()
        background = canvas.copy_from_bbox(figure.bbox)  # type: ignore[attr-defined]
        for index in indices:
            canvas.restore_region(background)  # type: ignore[attr-defined]
            frame.show(index)
            for artist in frame.moving:
                figure.draw_artist(artist)
            rgba = np.array(canvas.buffer_rgba())  # type: ignore[attr-defined]
            yield PILImage.fromarray(rgba, "RGBA")
    finally:
        for artist in frame.moving:
            artist.set_animated(False)


def _write_movie(figure: Figure, frame: Frame, indices: Iterable[int], path: Path,
                 writer_name: str, fps: int, dpi: float) -> None:
    """One full redraw per frame through matplotlib's writer (``ffmpeg`` for ``.mp4``)."""
    from matplotlib import animation as mpl_animation

    writer = mpl_animation.writers[writer_name](fps=fps)
    with writer.saving(figure, str(path), dpi):
        for index in indices:
            frame.show(index)
            writer.grab_frame()
