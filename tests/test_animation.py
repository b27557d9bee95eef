"""Frames and animations of a trajectory (wuerfel_cvx.animation, Trajectory.plot/animate)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from wuerfel_cvx import InputError, Scene, Square, Trajectory, simulate  # noqa: E402
from wuerfel_cvx.animation import (  # noqa: E402
    draw_frame,
    frame_indices,
    nearest_index,
    trajectory_model,
)
from wuerfel_cvx.cli import main  # noqa: E402

pytestmark = pytest.mark.integration


@pytest.fixture(scope="module")
def falling() -> Trajectory:
    """A unit square dropped from y = 2 m: 20 steps of 10 ms, still in the air."""
    return simulate("single-drop", dt=0.01, steps=20)


@pytest.fixture(autouse=True)
def _close_figures() -> None:
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


def test_model_rebuilt_from_a_trajectory_has_its_bodies() -> None:
    scene = Scene("two", (Square(center=(0.0, 0.5), size=0.5, angle=0.3),
                          Square(center=(2.0, 2.0))), Scene.named("single-drop").tables)
    model = trajectory_model(simulate(scene, steps=1))
    assert model.n_boxes == 2 and model.n_tables == 1
    np.testing.assert_allclose(model.box_sizes, [[0.5, 0.5], [1.0, 1.0]], rtol=1e-12)
    np.testing.assert_allclose(model.table_points, scene.table_points(), atol=1e-12)


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
