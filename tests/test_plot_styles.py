"""The report's plots tell series apart and keep their labels and legends off the data.

Colour: solver or engine; marker: formulation (a peer engine its own); fill: friction
model.  Log axes carry plain numbers, the Pareto front is ringed, legends stand outside
the axes.  The figures are taken from the plot functions before they are saved.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.collections import PathCollection
from matplotlib.figure import Figure

from wuerfel_cvx.lab.bench import plots, schema
from wuerfel_cvx.lab.bench.figures import plain_number
from wuerfel_cvx.lab.bench.styles import (
    FORMULATION_MARKERS,
    PEER_STYLES,
    SOLVER_STYLES,
    series_style,
)

pytestmark = pytest.mark.unit

Drawn = dict[str, Figure]


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> Iterator[Drawn]:
    """The figures the plot functions would save, by stem (nothing is written)."""
    from wuerfel_cvx.lab.bench import plots_accuracy, plots_cost

    figures: Drawn = {}

    def keep(figure: Figure, out_dir: Path, stem: str) -> list[Path]:
        figures[stem] = figure
        return [out_dir / f"{stem}.png"]

    for module in (plots_accuracy, plots_cost):
        monkeypatch.setattr(module, "save_figure", keep)
    yield figures


def results(tmp_path: Path, rows: list[dict[str, object]]) -> pd.DataFrame:
    """A typed results frame of completed grid points of scene ``s``."""
    path = tmp_path / "results.csv"
    for index, row in enumerate(rows):
        values = {"suite": "t", "point_id": f"p{index}", "scene": "s", "status": "ok",
                  "tol": "default", "dt": 0.01, "n_squares": 3, "engine": "wuerfel_cvx",
                  "wall_time_per_step_median": 1e-3 * (index + 1), **row}
        schema.append_row(path, schema.new_row(**values))
    return schema.read_results(path)


def point(formulation: str, solver: str, speed: float, error: float,
          model: str | None = "ccp") -> dict[str, object]:
    peer = formulation == "peer"
    return {"formulation": formulation, "solver": solver, "tol": "native" if peer else "default",
            "friction_model": None if peer else model, "wall_time_per_simulated_second": speed,
            "trajectory_error": error}


def scatters(figure: Figure) -> dict[str, PathCollection]:
    """The labelled point sets of a figure's first axes, by label."""
    return {str(c.get_label()): c for c in figure.axes[0].collections
            if isinstance(c, PathCollection)}


def marker_of(collection: PathCollection) -> np.ndarray:
    return np.asarray(collection.get_paths()[0].vertices)


def test_every_solver_and_engine_has_its_own_colour() -> None:
    colours = [colour for colour, _ in SOLVER_STYLES.values()]
    assert len(set(colours)) == len(colours)  # DAQP and PYMUNK were both brown


def test_formulations_and_peers_have_markers_of_their_own() -> None:
    markers = list(FORMULATION_MARKERS.values())
    peers = [marker for _, marker in PEER_STYLES.values()]
    assert len(set(markers)) == len(markers) and len(set(peers)) == len(peers)
    assert not set(markers) & set(peers)
    assert series_style("CLARABEL", "rigid").marker != series_style("CLARABEL", "velocity").marker
    assert series_style("CLARABEL", "rigid").colour == series_style("CLARABEL", "velocity").colour
    assert series_style("OSQP", "velocity", "ccp").filled
    assert not series_style("OSQP", "velocity", "coulomb").filled
    assert series_style("MUJOCO", "peer").marker == PEER_STYLES["MUJOCO"][1]


def test_headline_points_differ_by_formulation_and_friction_model(tmp_path: Path,
                                                                   drawn: Drawn) -> None:
    frame = results(tmp_path, [
        point("rigid", "CLARABEL", 0.1, 1e-9), point("velocity", "CLARABEL", 0.2, 1e-10),
        point("velocity", "OSQP", 0.3, 1e-8), point("velocity", "OSQP", 0.4, 1e-7, "coulomb"),
        point("peer", "MUJOCO", 0.01, 1e-2)])
    assert plots.plot_pareto_headline(frame, tmp_path)
    shown = scatters(drawn["pareto-headline"])
    rigid, velocity = shown["CLARABEL (rigid, ccp)"], shown["CLARABEL (velocity, ccp)"]
    assert not np.array_equal(marker_of(rigid), marker_of(velocity))
    np.testing.assert_array_equal(rigid.get_edgecolor(), velocity.get_edgecolor())
    ccp, coulomb = shown["OSQP (velocity, ccp)"], shown["OSQP (velocity, coulomb)"]
    np.testing.assert_array_equal(marker_of(ccp), marker_of(coulomb))
    assert ccp.get_facecolor()[0][3] == 1.0  # filled
    assert len(coulomb.get_facecolor()) == 0 or coulomb.get_facecolor()[0][3] == 0.0  # hollow
    legend = [text.get_text() for text in drawn["pareto-headline"].legends[0].get_texts()]
    assert {"CLARABEL (rigid, ccp)", "OSQP (velocity, coulomb)", "MUJOCO"} <= set(legend)


def test_the_pareto_front_is_ringed(tmp_path: Path, drawn: Drawn) -> None:
    frame = results(tmp_path, [
        point("velocity", "CLARABEL", 0.1, 1e-6), point("velocity", "OSQP", 0.2, 1e-8),
        point("velocity", "PIQP", 0.3, 1e-7), point("peer", "PYMUNK", 0.01, 1e-2)])
    assert plots.plot_pareto(frame, tmp_path)
    rings = scatters(drawn["pareto"])["Pareto front"]
    offsets = np.asarray(rings.get_offsets())
    expected = [(0.01, 1e-2), (0.1, 1e-6), (0.2, 1e-8)]  # PIQP is beaten by OSQP
    np.testing.assert_allclose(offsets, expected)
    assert len(rings.get_facecolor()) == 0 or rings.get_facecolor()[0][3] == 0.0


PLAIN = re.compile(r"^(-?\d+(\.\d+)?(e-?\d+)?)?$")


def tick_texts(figure: Figure) -> list[str]:
    figure.canvas.draw()
    return [label.get_text() for axis in figure.axes
            for part in (axis.xaxis, axis.yaxis)
            for label in part.get_ticklabels(which="both")]


def test_log_axes_within_a_decade_read_plain_numbers(tmp_path: Path, drawn: Drawn) -> None:
    # Errors of 1.2 to 1.7 m (the friction headline's peers): matplotlib would write 1.6×10⁰.
    frame = results(tmp_path, [
        point("peer", "PYMUNK", 0.002, 1.54), point("peer", "MUJOCO", 0.003, 1.7),
        point("velocity", "CLARABEL", 0.01, 1.45), point("velocity", "OSQP", 0.5, 1.24)])
    assert plots.plot_pareto_headline(frame, tmp_path)
    texts = tick_texts(drawn["pareto-headline"])
    assert all(PLAIN.match(text) for text in texts), texts
    labelled = [float(text) for text in texts if text]
    assert any(1.0 < value < 2.0 for value in labelled)  # minor ticks inside the decade


def test_plain_numbers_have_no_mathtext() -> None:
    assert [plain_number(v) for v in (1e-10, 2e-5, 1e-4, 0.001, 1.6, 20, 2000, 1e5)] == [
        "1e-10", "2e-5", "1e-4", "0.001", "1.6", "20", "2000", "1e5"]


def overlaps(a: object, b: object) -> bool:
    return bool(a.overlaps(b))  # type: ignore[attr-defined]


def test_legends_stand_beside_the_axes(tmp_path: Path, drawn: Drawn) -> None:
    frame = results(tmp_path, [
        point("velocity", solver, speed, error, model)
        for solver in ("CLARABEL", "OSQP", "PIQP") for model in ("ccp", "coulomb")
        for speed, error in ((0.1, 1e-9), (0.2, 1e-8))] + [
        {**point("velocity", "CLARABEL", 0.1, 1e-9), "scene": f"stack-{n}", "n_squares": n,
         "wall_time_per_step_median": 1e-4 * n} for n in (5, 10, 20)])
    assert plots.plot_pareto_headline(frame, tmp_path, scene="s")
    assert plots.plot_scaling(frame, tmp_path)
    for stem in ("pareto-headline", "scaling"):
        figure = drawn[stem]
        figure.canvas.draw()
        renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
        legends = [*figure.legends, *(axis.get_legend() for axis in figure.axes)]
        boxes = [legend.get_window_extent(renderer) for legend in legends if legend]
        assert boxes, stem
        for axis in figure.axes:
            assert not any(overlaps(box, axis.get_window_extent(renderer)) for box in boxes)
