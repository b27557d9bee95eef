"""Frames and animations of a trajectory (wuerfel_cvx.animation, Trajectory.plot/animate)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from PIL import Image  # noqa: E402

from wuerfel_cvx import InputError, Scene, Square, Trajectory, simulate  # noqa: E402
from wuerfel_cvx.animation import (  # noqa: E402
    Frame,
    animate,
    blitted_frames,
    draw_frame,
    frame_indices,
    model_from_corners,
    nearest_index,
    trajectory_model,
    view_limits,
)
from wuerfel_cvx.cli import main  # noqa: E402
from wuerfel_cvx.scenes.geometry import FloatArray, rectangle_corners  # noqa: E402
from wuerfel_cvx.scenes.scene import Table  # noqa: E402

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def falling() -> Trajectory:
    """A unit square dropped from y = 2 m: 20 steps of 10 ms, still in the air."""
    return simulate("single-drop", dt=0.01, steps=20)


@pytest.fixture(autouse=True)
def _close_figures() -> Iterator[None]:
    yield
    plt.close("all")


def test_frame_indices_follow_the_frame_rate() -> None:
    times = np.arange(201) * 0.01  # 2 s in 10 ms steps
    indices = frame_indices(times, fps=25.0, max_frames=300)
    # 25 frames per simulated second: every 4th state, first and last included.
    np.testing.assert_array_equal(indices, np.arange(0, 201, 4))


def test_frame_indices_are_capped_and_keep_the_ends() -> None:
    times = np.arange(10_001) * 1e-4
    indices = frame_indices(times, fps=100.0, max_frames=12)
    assert len(indices) == 12
    assert indices[0] == 0 and indices[-1] == 10_000
    assert np.all(np.diff(indices) > 0)


def test_frame_indices_never_repeat_a_state_for_coarse_steps() -> None:
    times = np.arange(11) * 0.1  # 10 fps of states, 25 fps asked: each state once
    np.testing.assert_array_equal(frame_indices(times, fps=25.0), np.arange(11))


@pytest.mark.parametrize("fps, max_frames", [(0.0, 10), (float("nan"), 10), (25.0, 1)])
def test_frame_indices_reject_bad_settings(fps: float, max_frames: int) -> None:
    with pytest.raises(InputError):
        frame_indices(np.arange(5) * 0.1, fps=fps, max_frames=max_frames)


def test_nearest_index_rounds_to_the_closest_state() -> None:
    times = np.arange(21) * 0.01
    assert nearest_index(times, 0.093) == 9
    assert nearest_index(times, 0.097) == 10
    assert nearest_index(times, 5.0) == 20


def test_frame_of_a_resting_stack_marks_every_touching_corner() -> None:
    trajectory = simulate("stack-3", dt=0.01, steps=2)
    frame = draw_frame(trajectory, 0)
    assert len(frame.squares.get_paths()) == 3
    assert len(frame.tables.get_paths()) == 1
    # By hand: 2 corners on the floor, and at each of the 2 interfaces the lower square's
    # 2 top corners and the upper square's 2 bottom corners.
    assert len(frame.contacts.get_offsets()) == 2 + 2 * 4
    assert frame.axes.get_xlabel() == "x (m)" and frame.axes.get_ylabel() == "y (m)"
    assert frame.axes.get_aspect() == 1.0


def test_frame_of_a_square_in_flight_has_no_contact(falling: Trajectory) -> None:
    frame = draw_frame(falling, 5)
    assert len(frame.squares.get_paths()) == 1
    assert len(frame.contacts.get_offsets()) == 0
    assert "step 5" in frame.label.get_text()


def test_plot_takes_the_nearest_state_and_returns_axes(falling: Trajectory) -> None:
    ax = falling.plot(0.093)
    texts = [text.get_text() for text in ax.texts]
    assert any("step 9" in text and "t = 0.090 s" in text for text in texts)
    corners = ax.collections[1].get_paths()[0].vertices[:4]
    np.testing.assert_allclose(corners, falling.points[9], atol=1e-12)


def test_model_of_a_trajectory_is_the_recorded_scenes() -> None:
    scene = Scene("two", (Square(center=(0.0, 0.5), size=0.5, angle=0.3, mass=3.0),
                          Square(center=(2.0, 2.0))), Scene.named("single-drop").tables)
    model = trajectory_model(simulate(scene, steps=1))
    assert model.scene == scene  # from info["scene_data"], masses and all
    np.testing.assert_allclose(model.point_masses, [0.75] * 4 + [0.25] * 4)


def test_model_of_an_old_file_is_rebuilt_from_its_corners() -> None:
    scene = Scene("two", (Square(center=(0.0, 0.5), size=0.5, angle=0.3),
                          Square(center=(2.0, 2.0))), Scene.named("single-drop").tables)
    trajectory = simulate(scene, steps=1)
    del trajectory.info["scene_data"]  # as written before trajectories carried their scene
    model = trajectory_model(trajectory)
    assert model.n_boxes == 2 and model.n_tables == 1
    np.testing.assert_allclose(model.box_sizes, [[0.5, 0.5], [1.0, 1.0]], rtol=1e-12)
    np.testing.assert_allclose(model.scene.initial_points(), trajectory.points[0], atol=1e-12)
    np.testing.assert_allclose(model.table_points, scene.table_points(), atol=1e-12)


def test_corner_fallback_takes_both_side_lengths_of_a_box() -> None:
    plank = rectangle_corners((0.0, 1.0), 2.0, 0.5, 0.2)
    trajectory = Trajectory(times=np.zeros(1), points=plank[None], velocities=0 * plank[None],
                            metrics=None,  # type: ignore[arg-type]  # not read
                            table_points=Table(center=(0.0, -0.5)).corners())
    try:
        model = model_from_corners(trajectory)
    except InputError as error:  # the scene schema has no [[boxes]] yet
        assert "boxes" in str(error)
        pytest.skip("scene files have no [[boxes]] yet: " + str(error))
    np.testing.assert_allclose(model.box_sizes, [[2.0, 0.5]], rtol=1e-12)
    np.testing.assert_allclose(model.scene.initial_points(), plank, atol=1e-12)


# ------------------------------------------------------------ view and label
def _drawn(trajectory: Trajectory, index: int) -> tuple[Figure, Frame]:
    figure = Figure(figsize=(6.0, 4.5), dpi=80)
    FigureCanvasAgg(figure)
    frame = draw_frame(trajectory, index, figure.subplots())
    figure.tight_layout()
    figure.canvas.draw()
    return figure, frame


@pytest.mark.parametrize("name", ["stack-10", "pyramid-4", "heavy-on-light-100"])
def test_time_label_is_above_every_body(name: str) -> None:
    trajectory = simulate(name, steps=2)
    _, frame = _drawn(trajectory, 2)
    label = frame.label.get_window_extent()
    axes = frame.axes.get_window_extent()
    title = frame.axes.title.get_window_extent()
    # Every body is inside the axes (the limits hold them), and the label is outside.
    (x0, x1), (y0, y1) = frame.axes.get_xlim(), frame.axes.get_ylim()
    points = trajectory.points.reshape(-1, 2)
    assert np.all((points[:, 0] > x0) & (points[:, 0] < x1))
    assert np.all((points[:, 1] > y0) & (points[:, 1] < y1))
    assert label.y0 >= axes.y1  # above the axes' top edge: over no body
    assert title.y0 >= label.y1  # and below the title, not over it
    assert "t = 0.020 s" in frame.label.get_text() and "step 2" in frame.label.get_text()


def _table_corners(trajectory: Trajectory) -> FloatArray:
    return np.asarray(trajectory.table_points).reshape(-1, 2)


def _inside(points: FloatArray, limits: tuple[tuple[float, float], ...]) -> bool:
    (x0, x1), (y0, y1) = limits
    return bool(np.all((points[:, 0] >= x0) & (points[:, 0] <= x1)
                       & (points[:, 1] >= y0) & (points[:, 1] <= y1)))


def test_view_holds_the_wall_and_every_bodys_path() -> None:
    trajectory = simulate("wall-contact", steps=40)
    limits = view_limits(trajectory, np.arange(trajectory.n_steps + 1))
    wall = np.asarray(trajectory.table_points).reshape(-1, 4, 2)[1]  # 1 m x 3 m, x 2..3
    assert _inside(wall, limits)
    assert _inside(trajectory.points.reshape(-1, 2), limits)


def test_view_holds_a_tilted_and_a_far_table() -> None:
    # Each smaller than the square's view (2 m): held whole, however far.
    tables = (Table(center=(0.0, -0.5), size=(3.0, 0.5), angle=0.3),
              Table(center=(6.0, 5.0), size=(1.0, 1.0), angle=0.7))
    scene = Scene("far", (Square(center=(0.0, 2.0)),), tables)
    trajectory = simulate(scene, steps=3)
    assert _inside(_table_corners(trajectory),
                   view_limits(trajectory, np.arange(trajectory.n_steps + 1)))


def test_a_long_floor_fills_the_view_without_shrinking_the_bodies() -> None:
    trajectory = simulate("tilted-drop", steps=3)  # a 40 m floor under a 1 m square
    (x0, x1), (y0, y1) = view_limits(trajectory, np.arange(trajectory.n_steps + 1))
    floor = _table_corners(trajectory)
    assert floor[:, 0].min() < x0 and x1 < floor[:, 0].max()  # runs on beyond both sides
    bodies = trajectory.points.reshape(-1, 2)
    # Only the bodies' margin (0.5 m here) beside them, not the floor's 40 m.
    assert x0 == pytest.approx(bodies[:, 0].min() - 0.5)
    assert x1 == pytest.approx(bodies[:, 0].max() + 0.5)
    assert y0 <= floor[:, 1].min()  # its full thickness is in view


def test_a_deep_ground_is_cropped_to_the_margin_under_the_bodies() -> None:
    # The card house (1.8 m tall) stands on a ground 80 m wide and 4 m deep: the view is
    # the house and its margin, not two thirds ground.
    trajectory = simulate("card-house", dt=1.0 / 60.0, steps=1)
    (x0, x1), (y0, y1) = view_limits(trajectory, np.arange(trajectory.n_steps + 1))
    bodies = trajectory.points.reshape(-1, 2)
    low, high = bodies.min(axis=0), bodies.max(axis=0)
    margin = 0.5  # at least 0.5 m, a tenth of the bodies' extent above that
    assert (x0, x1) == (pytest.approx(low[0] - margin), pytest.approx(high[0] + margin))
    assert (y0, y1) == (pytest.approx(low[1] - margin), pytest.approx(high[1] + margin))
    ground = _table_corners(trajectory)
    assert ground[:, 1].min() == pytest.approx(-4.0) and ground[:, 1].max() == pytest.approx(0.0)
    assert (high[1] - low[1]) / (y1 - y0) > 0.6  # the house fills the frame's height


def test_a_table_as_long_as_the_view_beside_it_is_held_whole() -> None:
    # A 1 m square on a floor 2 m deep: the floor's part below the square's view (1.5 m)
    # is shorter than the view (2 m), so all of it is shown; 3 m deep, it is cropped.
    for depth, whole in ((2.0, True), (3.0, False)):
        floor = Table(center=(0.0, -depth / 2), size=(3.0, depth))
        trajectory = simulate(Scene("floor", (Square(center=(0.0, 0.5)),), (floor,)), steps=1)
        (_, _), (y0, _) = view_limits(trajectory, np.arange(trajectory.n_steps + 1))
        assert y0 == (pytest.approx(-depth - 0.1) if whole else pytest.approx(-0.5))


# -------------------------------------------------------------------- GIFs
def test_blitted_frames_are_the_full_redraws() -> None:
    trajectory = simulate("stack-3", dt=0.01, steps=6)
    indices = [0, 3, 6]
    figure = Figure(figsize=(4.0, 3.0), dpi=50)
    FigureCanvasAgg(figure)
    frame = draw_frame(trajectory, 0, figure.subplots(), indices=np.array(indices))
    figure.tight_layout()
    fast = [np.asarray(image) for image in blitted_frames(figure, frame, indices)]
    for index, image in zip(indices, fast, strict=True):
        full = Figure(figsize=(4.0, 3.0), dpi=50)
        FigureCanvasAgg(full)
        draw_frame(trajectory, index, full.subplots(), indices=np.array(indices))
        full.tight_layout()
        full.canvas.draw()
        np.testing.assert_array_equal(image, np.asarray(full.canvas.buffer_rgba()))


@pytest.mark.parametrize("progress", [True, False])
def test_gif_progress_goes_to_stderr(progress: bool, falling: Trajectory, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    animate(falling, tmp_path / "bar.gif", fps=50.0, dpi=30, figsize=(3.0, 2.5),
            progress=progress)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert ("bar.gif:" in captured.err and "frame" in captured.err) is progress


def test_gif_has_the_subsampled_frame_count(falling: Trajectory, tmp_path: Path) -> None:
    path = falling.animate(tmp_path / "drop.gif", fps=25.0, dpi=30, figsize=(3.0, 2.5))
    with Image.open(path) as image:
        # 0.2 s at 25 fps: states 0, 4, 8, 12, 16, 20.
        assert image.format == "GIF"
        assert image.n_frames == 6


def test_gif_respects_the_frame_cap(falling: Trajectory, tmp_path: Path) -> None:
    path = falling.animate(tmp_path / "capped.gif", fps=100.0, max_frames=3, dpi=30,
                           figsize=(3.0, 2.5))
    with Image.open(path) as image:
        assert image.n_frames == 3


def test_unsupported_suffix_is_an_input_error(falling: Trajectory, tmp_path: Path) -> None:
    with pytest.raises(InputError, match="unsupported animation format '.avi'"):
        falling.animate(tmp_path / "drop.avi")


def test_mp4_without_ffmpeg_is_an_input_error(falling: Trajectory, tmp_path: Path,
                                              monkeypatch: pytest.MonkeyPatch) -> None:
    from matplotlib import animation

    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    with pytest.raises(InputError, match="needs ffmpeg"):
        falling.animate(tmp_path / "drop.mp4")


def test_unwritable_path_is_an_input_error(falling: Trajectory, tmp_path: Path) -> None:
    blocker = tmp_path / "a-file"
    blocker.write_text("not a directory")
    with pytest.raises(InputError, match="cannot write"):
        falling.animate(blocker / "drop.gif", dpi=30, figsize=(3.0, 2.5))


def test_cli_animate_writes_the_gif(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cli.gif"
    status = main(["simulate", "single-drop", "--steps", "10", "--fps", "50",
                   "--animate", str(out)])
    assert status == 0
    assert f"wrote {out}" in capsys.readouterr().out
    with Image.open(out) as image:
        assert image.n_frames == 6  # 0.1 s at 50 fps: states 0, 2, 4, 6, 8, 10


def test_cli_rejects_a_bad_suffix_before_simulating(tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    status = main(["simulate", "single-drop", "--steps", "10", "--animate",
                   str(tmp_path / "out.txt")])
    captured = capsys.readouterr()
    assert status == 2
    assert "unsupported animation format '.txt'" in captured.err
    assert captured.out == ""  # no summary: the run never started


def _ffmpeg_available() -> bool:
    from matplotlib import animation

    return bool(animation.writers.is_available("ffmpeg"))


@pytest.mark.skipif(not _ffmpeg_available(), reason="ffmpeg is not installed")
def test_mp4_is_written_where_ffmpeg_exists(falling: Trajectory, tmp_path: Path) -> None:
    path = falling.animate(tmp_path / "drop.mp4", dpi=30, figsize=(3.0, 2.5))
    assert path.read_bytes()[4:8] == b"ftyp"  # the MP4 container's first box
