"""The overlap depth of bodies (separating axis), and its column in the results table."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest

from wuerfel_cvx import Scene
from wuerfel_cvx.lab.bench import schema
from wuerfel_cvx.lab.bench.runner import run_point
from wuerfel_cvx.lab.bench.suite import GridPoint
from wuerfel_cvx.scenes.geometry import polygon_overlap_depth, rectangle_corners
from wuerfel_cvx.scenes.library import FLOOR
from wuerfel_cvx.scenes.scene import Box, Square
from wuerfel_cvx.step.metrics import deepest_overlap, deepest_penetration
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.unit


def test_overlap_of_two_boxes_is_the_separating_axis_depth() -> None:
    # against geometry.polygon_overlap_depth (edge_distances, the contact's signed areas):
    # a second implementation, on poses from apart to deeply overlapping
    sizes = ((0.8, 0.3), (0.5, 1.2))
    scene = Scene("two", boxes=tuple(Box(center=(3.0 * k, 5.0), size=s)
                                    for k, s in enumerate(sizes)))
    model = Model.from_scene(scene)
    rng = np.random.default_rng(12)
    overlapping = 0
    for _ in range(300):
        poses = [(rng.uniform(-0.6, 0.6, size=2), rng.uniform(-math.pi, math.pi))
                 for _ in sizes]
        corners = [rectangle_corners(centre, w, h, angle)
                   for (centre, angle), (w, h) in zip(poses, sizes, strict=True)]
        expected = polygon_overlap_depth(*corners)
        overlapping += expected > 0
        assert deepest_overlap(model, np.concatenate(corners)) == pytest.approx(
            expected, rel=1e-12, abs=1e-15)
    assert 50 < overlapping < 300  # both cases were tried


def test_overlap_with_a_table_and_apart() -> None:
    scene = Scene("one", (Square(center=(0.0, 2.0)),), (FLOOR,))
    model = Model.from_scene(scene)
    sunk = rectangle_corners((0.0, 0.5 - 0.03), 1.0, 1.0, 0.0)  # 3 cm into the floor
    assert deepest_overlap(model, sunk) == pytest.approx(0.03, rel=1e-12)
    assert deepest_overlap(model, scene.initial_points()) == 0.0  # 1.5 m above it


@pytest.mark.parametrize("name", ["corner-overlap", "corner-overlap-wedged"])
def test_overlap_sees_the_corners_that_are_shallow_only_across_a_side_face(name: str) -> None:
    # each corner is 1e-7 m inside a side face's line but 2e-4 to 5e-4 m beyond a top
    # or bottom face: the bodies cannot be separated by less than the latter.  The
    # per-pair contacts measure along the separating axis too: both metrics agree
    scene = Scene.named(name)
    model = Model.from_scene(scene)
    points = scene.initial_points()
    lower, upper = (s.corners() for s in scene.squares)
    assert deepest_overlap(model, points) == pytest.approx(polygon_overlap_depth(lower, upper))
    assert deepest_overlap(model, points) > 1e-4
    assert deepest_penetration(model, points) == pytest.approx(deepest_overlap(model, points),
                                                               rel=1e-6)


@pytest.mark.integration
def test_results_row_has_the_overlap_depth() -> None:
    # the start-linearised rows leave the overlap in place over these 3 steps
    point = GridPoint(suite="t", scene="corner-overlap", formulation="velocity-baumgarte",
                      solver="CLARABEL", tol="default", dt=0.01, duration=0.03,
                      reference="none", compare_every=0)
    row = run_point(point, None)
    assert row["status"] == "ok" and row["steps_completed"] == 3
    # a corner inside a body is at least its depth from every exit, so it takes at least
    # that translation to separate the two: the overlap bounds the penetration.  Here the
    # deepest corner is measured against the same face by both, so the two are equal up
    # to the round-off of their different arithmetic (a few ulps)
    assert row["max_overlap_depth"] >= row["max_penetration"] * (1.0 - 1e-14)
    assert row["max_penetration"] > 0.0
    assert row["max_overlap_depth"] > 1e-4


def test_results_of_schema_version_4_are_read_without_the_overlap_depth(tmp_path: Path) -> None:
    row = schema.new_row(suite="t", point_id="p", scene="stack-3", max_penetration=1e-6,
                         max_overlap_depth=2e-6)
    since = {name for version in range(5, schema.SCHEMA_VERSION + 1)
             for name in schema.ADDED_COLUMNS[version]}
    names = [name for name in schema.COLUMN_NAMES if name not in since]
    old = tmp_path / "results.csv"
    with old.open("w", encoding="utf-8", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=names, extrasaction="ignore")
        writer.writeheader()
        writer.writerow({**row, "schema_version": 4})
    frame = schema.read_results(old)
    assert (frame["schema_version"] == schema.SCHEMA_VERSION).all()
    assert frame["max_overlap_depth"].isna().all()  # not measured then: missing, not 0
    assert frame["max_penetration"].iloc[0] == 1e-6
