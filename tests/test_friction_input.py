"""The ``friction`` key of scene files, and the contacts' mixed coefficient."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wuerfel_cvx import InputError, Scene, simulate
from wuerfel_cvx.friction.forces import body_friction, contact_friction, is_frictionless
from wuerfel_cvx.step.contacts import find_contacts
from wuerfel_cvx.step.model import Model

pytestmark = pytest.mark.unit

RESTING = {
    "name": "resting", "gravity": [0.0, -9.81],
    "tables": [{"center": [0.0, -0.5], "size": [10.0, 1.0], "friction": 0.5}],
    "squares": [{"center": [0.0, 0.5], "friction": 0.8}],
    "boxes": [{"center": [3.0, 0.25], "size": [2.0, 0.5]}],
}


def test_friction_is_read_for_every_kind_of_body_and_defaults_to_zero() -> None:
    scene = Scene.from_dict(RESTING)
    np.testing.assert_array_equal(body_friction(scene), [0.8, 0.0, 0.5])
    assert not is_frictionless(scene)
    assert is_frictionless(Scene.named("stack-3"))


def test_a_contact_takes_the_geometric_mean_of_its_bodies() -> None:
    scene = Scene.from_dict(RESTING)
    model = Model.from_scene(scene)
    contacts = find_contacts(model, scene.initial_points(), 0.01)
    mixed = contact_friction(body_friction(scene), contacts)
    square_on_table = (contacts.point_body == 0) | (contacts.edge_body == 0)
    assert square_on_table.any() and (~square_on_table).any()
    np.testing.assert_allclose(mixed[square_on_table], math.sqrt(0.8 * 0.5), rtol=1e-15)
    np.testing.assert_array_equal(mixed[~square_on_table], 0.0)  # the frictionless box


def test_friction_survives_a_round_trip_and_is_written_only_when_set() -> None:
    scene = Scene.from_dict(RESTING)
    data = scene.to_dict()
    assert Scene.from_dict(data) == scene
    assert data["squares"][0]["friction"] == 0.8 and data["tables"][0]["friction"] == 0.5
    assert "friction" not in data["boxes"][0]
    assert all("friction" not in body for body in Scene.named("stack-3").to_dict()["squares"])


@pytest.mark.integration
def test_a_frictionless_scene_runs_as_before() -> None:
    # the key at 0 is the default: the same scene, the same trajectory
    stated = dict(RESTING, tables=[{"center": [0.0, -0.5], "size": [10.0, 1.0],
                                    "friction": 0.0}],
                  squares=[{"center": [0.0, 0.5], "friction": 0.0}])
    plain = dict(RESTING, tables=[{"center": [0.0, -0.5], "size": [10.0, 1.0]}],
                 squares=[{"center": [0.0, 0.5]}])
    assert Scene.from_dict(stated) == Scene.from_dict(plain)
    a = simulate(Scene.from_dict(stated), steps=5)
    b = simulate(Scene.from_dict(plain), steps=5)
    np.testing.assert_array_equal(a.points, b.points)


@pytest.mark.parametrize(("value", "message"), [
    (-0.1, "must be non-negative"), (float("nan"), "must be finite"),
    (1e3, "out of range"), ("high", "expected a number"), (True, "expected a number"),
])
@pytest.mark.parametrize("group", ["squares", "tables"])
def test_bad_friction_is_one_line_naming_the_field(group: str, value: object,
                                                   message: str) -> None:
    data = {**RESTING, group: [{**RESTING[group][0], "friction": value}]}
    with pytest.raises(InputError, match=message) as caught:
        Scene.from_dict(data)
    assert f"{group}[0].friction" in str(caught.value)
    assert "\n" not in str(caught.value)
