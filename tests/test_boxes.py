"""Boxes of any width x height: the ``[[boxes]]`` schema, the model, and their physics.

A box is 4 corner masses ``m / 4`` joined by 5 rods of its own side and diagonal
lengths, so its moment of inertia about the centre is ``m (w^2 + h^2) / 4``.  The
headline case is the library's ``plank-drop``: a 2 x 0.5 m plank dropped at 0.3 rad
settles flat, 0.25 m up, with exact side lengths.  Every tolerance is derived from the
solver setting, Baumgarte's ``beta`` or round-off, as each comment says.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.cli import main
from wuerfel_cvx.errors import InputError
from wuerfel_cvx.formulations import VelocityFormulation
from wuerfel_cvx.formulations.rigid import body_velocities
from wuerfel_cvx.lab.robustness.fuzz import run_fuzz, seed_files
from wuerfel_cvx.lab.robustness.properties import ASPECT_RANGE, random_scene
from wuerfel_cvx.scenes.library import DOMINO_COUNT, FLOOR, PLANK_SIZE
from wuerfel_cvx.scenes.scene import LIMITS, Box, Square, Table
from wuerfel_cvx.solve.paths import VERIFY_FACTOR
from wuerfel_cvx.solve.registry import TOLERANCE_PRESETS
from wuerfel_cvx.step.metrics import kinetic_energy
from wuerfel_cvx.step.model import BOX_RODS, Model, State
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
DT = 0.01
G = 9.81
EPS = float(np.finfo(np.float64).eps)
EPS_HIGH = TOLERANCE_PRESETS["high"]
VELOCITY = VelocityFormulation()
PLANK_MASS = 1.0


def box_angles(traj: Trajectory, body: int = 0) -> np.ndarray:
    """Angle (rad) of a body's first edge (corner 0 to 1) in every state."""
    edge = traj.points[:, 4 * body + 1] - traj.points[:, 4 * body]
    return np.asarray(np.arctan2(edge[:, 1], edge[:, 0]))


def rigid_round_off(traj: Trajectory, shortest_rod: float) -> float:
    """Largest relative rod error (1) that round-off alone leaves after a step.

    The rigid position update rebuilds every corner from the exact reference corners (a
    rotation and a translation), so the error does not accumulate: a rod's length is
    off by a few ulps of the coordinates.  Eight ulps of the largest coordinate (m),
    relative to the shortest rod (m).
    """
    largest = float(np.max(np.abs(traj.points)))
    return 8.0 * EPS * max(largest, 1.0) / shortest_rod


# ------------------------------------------------------------------ schema and model
def test_boxes_load_from_toml_as_the_library_scenes() -> None:
    plank = Scene.from_toml(EXAMPLES / "plank-drop.toml")
    assert plank == Scene.named("plank-drop")
    assert plank.squares == () and plank.n_boxes == 1
    assert plank.boxes == (Box(center=(0.0, 1.5), size=(2.0, 0.5), angle=0.3, mass=1.0),)
    dominoes = Scene.from_toml(EXAMPLES / "domino-row.toml")
    assert dominoes == Scene.named("domino-row")
    assert dominoes.n_boxes == DOMINO_COUNT


def test_omitted_box_keys_take_the_squares_defaults(tmp_path: Path) -> None:
    path = tmp_path / "box.toml"
    path.write_text("[[boxes]]\ncenter = [1, 2]\n", encoding="utf-8")
    (box,) = Scene.from_toml(path).boxes
    assert box == Box(center=(1.0, 2.0), size=(1.0, 1.0), angle=0.0, mass=1.0,
                      velocity=(0.0, 0.0), angular_velocity=0.0)
    assert isinstance(box.size[0], float)  # TOML integers become floats


def test_to_dict_round_trips_squares_and_boxes_exactly() -> None:
    scene = Scene(
        "mixed",
        (Square(center=(-3.0, 4.0), size=0.5, angle=-1.2, mass=2.5, velocity=(1.0, -2.0),
                angular_velocity=7.0),),
        (Table(center=(0.0, -1.0), size=(8.0, 2.0), angle=0.05),),
        gravity=(1.0, -3.0),
        boxes=(Box(center=(3.0, 1.0), size=(2.0, 0.3), angle=0.7, mass=0.4,
                   velocity=(0.1, 0.2), angular_velocity=-0.3),
               Box(center=(6.0, 1.0), size=(0.25, 1.75))),
    )
    data = scene.to_dict()
    assert data["boxes"][0] == {"center": [3.0, 1.0], "size": [2.0, 0.3], "angle": 0.7,
                                "mass": 0.4, "velocity": [0.1, 0.2],
                                "angular_velocity": -0.3}
    again = Scene.from_dict(data)
    assert again == scene
    assert again.to_dict() == data
    np.testing.assert_array_equal(again.initial_points(), scene.initial_points())
    # a scene of squares alone keeps the seed's schema: no empty `boxes` array
    assert "boxes" not in Scene.named("tilted-drop").to_dict()


def test_a_trajectory_rebuilds_its_box_scene() -> None:
    scene = Scene.named("plank-drop")
    traj = simulate(scene, dt=DT, steps=2)
    assert traj.scene == scene
    np.testing.assert_array_equal(traj.points[0], scene.initial_points())


def test_bodies_are_squares_then_boxes_in_every_array() -> None:
    square = Square(center=(5.0, 3.0), size=0.5, mass=2.0)
    box = Box(center=(0.0, 3.0), size=(2.0, 0.5), angle=0.4, mass=3.0)
    scene = Scene("order", (square,), boxes=(box,))
    assert scene.bodies == (square, box)
    points = scene.initial_points()
    np.testing.assert_array_equal(points[:4], square.corners())
    np.testing.assert_array_equal(points[4:], box.corners())
    model = Model.from_scene(scene)
    np.testing.assert_array_equal(model.box_sizes, [[0.5, 0.5], [2.0, 0.5]])
    np.testing.assert_array_equal(model.point_masses, [0.5] * 4 + [0.75] * 4)
    np.testing.assert_array_equal(State.initial(scene).points, points)


def test_a_box_of_equal_sides_is_a_square_bit_for_bit() -> None:
    kwargs = {"center": (0.3, 1.7), "angle": 0.9, "mass": 2.0, "velocity": (1.0, -0.5),
              "angular_velocity": 4.0}
    square = Square(size=0.8, **kwargs)  # type: ignore[arg-type]
    box = Box(size=(0.8, 0.8), **kwargs)  # type: ignore[arg-type]
    np.testing.assert_array_equal(box.corners(), square.corners())
    np.testing.assert_array_equal(box.corner_velocities(), square.corner_velocities())
    as_square = Model.from_scene(Scene("s", (square,)))
    as_box = Model.from_scene(Scene("b", boxes=(box,)))
    for name in ("box_sizes", "point_masses", "rods", "rod_lengths", "reference_corners"):
        np.testing.assert_array_equal(getattr(as_box, name), getattr(as_square, name))


def test_rods_have_the_boxs_own_side_and_diagonal_lengths() -> None:
    width, height = PLANK_SIZE
    model = Model.from_scene(Scene.named("plank-drop"))
    assert [tuple(r) for r in model.rods] == list(BOX_RODS)
    np.testing.assert_allclose(model.rod_lengths,
                               [width, height, width, height, math.hypot(width, height)],
                               rtol=4 * EPS)
    # the moment of the four corner masses about the centre: m (w^2 + h^2) / 4
    masses = model.point_masses.reshape(-1, 4)
    inertia = np.sum(masses * np.sum(model.reference_corners**2, axis=2), axis=1)
    assert inertia[0] == pytest.approx(PLANK_MASS * (width**2 + height**2) / 4, rel=4 * EPS)


@pytest.mark.parametrize("formulation", ["velocity", "rigid"])
def test_a_spinning_plank_has_the_kinetic_energy_of_its_moment(formulation: str) -> None:
    """Free flight without gravity: KE = m |v|^2 / 2 + I omega^2 / 2, I = m (w^2 + h^2)/4.

    No force acts, so both formulations keep the centre velocity and the spin exactly
    (the rigid update conserves the angular momentum about the centre): the energy and
    the angle advance hold to round-off.
    """
    width, height, mass, omega, velocity = 2.0, 0.5, 3.0, 5.0, (1.0, 0.5)
    plank = Box(center=(0.0, 0.0), size=(width, height), angle=0.2, mass=mass,
                velocity=velocity, angular_velocity=omega)
    scene = Scene("spinning-plank", boxes=(plank,), gravity=(0.0, 0.0))
    inertia = mass * (width**2 + height**2) / 4
    expected = mass * float(np.dot(velocity, velocity)) / 2 + inertia * omega**2 / 2
    model = Model.from_scene(scene)
    assert kinetic_energy(model, State.initial(scene)) == pytest.approx(expected, rel=1e-14)
    steps = 100
    traj = simulate(scene, dt=DT, steps=steps, formulation=formulation, tol="high")
    energy = traj.metrics["kinetic_energy_J"].to_numpy()
    np.testing.assert_allclose(energy, expected, rtol=1e-12)  # round-off over 100 steps
    unwrapped = np.unwrap(box_angles(traj))
    np.testing.assert_allclose(unwrapped, 0.2 + omega * traj.times, atol=1e-12)
    _, spin = body_velocities(traj.points[-1], traj.velocities[-1], np.ones((1, 4)))
    assert spin[0] == pytest.approx(omega, rel=1e-12)
    assert traj.metrics["rod_drift"].max() <= rigid_round_off(traj, height)


# ------------------------------------------------------------------ the plank drop
def rest_tolerance(mass: float) -> float:
    """How far (m) a corner resting on the floor may sit from it after a verified step.

    Both from the residual check, relative residuals at most ``VERIFY_FACTOR * eps``
    (eps = 1e-9, ``high``), with the primal scale ``S = 1 + margin / dt + 2 dt g``
    (right-hand sides ``|d| / dt <= margin / dt``, rows ``|G v+| ~ 0`` at rest, gravity's
    share; see :func:`wuerfel_cvx.solve.paths.kkt_residuals`):

    * below (Baumgarte): the rate error ``r S`` lets a corner sink ``dt r S`` per step
      while ``beta`` of the depth is removed, a fixed point of ``dt r S / beta``;
    * above (speculative row ``d + dt v_n >= 0``): the row's slack ``s`` leaves the
      corner ``dt s`` up, and complementarity ``c = nu s / (1 + nu S)`` bounds ``s`` by
      ``c (1 + nu S) / nu``, where ``nu = m g dt`` is twice (the objective has no 1/2)
      the impulse of either of the two bottom corners, each carrying half the weight.

    Plus 1e-14 m of round-off (coordinates of 2 m at 2.2e-16 relative).
    """
    residual = VERIFY_FACTOR * EPS_HIGH
    scale = 1.0 + VELOCITY.contact_margin / DT + 2.0 * DT * G
    multiplier = mass * G * DT
    below = DT * residual * scale / VELOCITY.beta
    above = DT * residual * (1.0 + multiplier * scale) / multiplier
    return max(below, above) + 1e-14


def landing_penetration_bound(traj: Trajectory, radius: float) -> float:
    """Largest depth (m) the velocity formulation allows a landing (properties.py's bound).

    Over a step the depth of a spinning corner departs from its first-order prediction
    by at most ``dt^2 / 2 (4 Omega^2 R + 4 Omega V)`` (``Omega`` the spin, ``V`` the
    largest corner speed, ``R`` the half diagonal), plus ``dt r S`` from the residuals;
    Baumgarte removes ``beta`` of the depth per step, so the depth stays below the
    recursion's fixed point: that overshoot over ``beta``.
    """
    _, spin = body_velocities(traj.points.reshape(-1, 2), traj.velocities.reshape(-1, 2),
                              np.ones((traj.points.shape[0], 4)))
    omega = float(np.max(np.abs(spin)))
    speed = float(np.max(np.linalg.norm(traj.velocities, axis=2)))
    scale = 1.0 + 6.0 * speed + VELOCITY.contact_margin / DT + 2.0 * DT * G
    overshoot = (DT**2 / 2 * (4 * omega**2 * radius + 4 * omega * speed)
                 + DT * VERIFY_FACTOR * EPS_HIGH * scale)
    return overshoot / VELOCITY.beta


def assert_plank_settled_flat(traj: Trajectory) -> None:
    """The plank lies on a long side at rest, exactly rigid, barely in the floor."""
    width, height = PLANK_SIZE
    tolerance = rest_tolerance(PLANK_MASS)  # 1.2e-8 m
    assert traj.metrics["verified"].all()  # so the residuals are within the check
    final = traj.points[-1]
    # flat: the angle is a multiple of pi (on either long side) to within two corners'
    # height tolerance across the width
    assert abs(math.remainder(float(box_angles(traj)[-1]), math.pi)) <= 2 * tolerance / width
    lowest_two = np.sort(final[:, 1])[:2]
    np.testing.assert_allclose(lowest_two, 0.0, atol=tolerance)
    assert float(final[:, 1].mean()) == pytest.approx(height / 2, abs=tolerance)
    # at rest: moving less than the tolerance per step
    assert float(np.max(np.linalg.norm(traj.velocities[-1], axis=1))) <= tolerance / DT
    # frictionless floor: no horizontal force, so the centre stays at x = 0
    assert abs(float(final[:, 0].mean())) <= 1e-12
    # the rigid position update keeps every rod exact
    assert traj.metrics["rod_drift"].max() <= rigid_round_off(traj, height)
    depth = traj.metrics["penetration_m"].to_numpy()
    assert depth.max() <= landing_penetration_bound(traj, math.hypot(width, height) / 2)
    assert depth[-50:].max() <= tolerance  # the last half second, at rest


@pytest.mark.parametrize("solver", ["CLARABEL", "OSQP", "PIQP"])
def test_a_plank_dropped_at_a_tilt_settles_flat_with_exact_side_lengths(solver: str) -> None:
    traj = simulate("plank-drop", dt=DT, steps=200, solver=solver, tol="high")  # lands ~0.45 s
    assert_plank_settled_flat(traj)


def test_the_rigid_formulation_settles_the_plank_flat_too() -> None:
    rigid = simulate("plank-drop", dt=DT, steps=200, formulation="rigid", tol="high")
    assert_plank_settled_flat(rigid)
    # the same QP in other unknowns while the rods hold, so the same motion: each step's
    # velocities may differ by the verified residual times the velocity scale (1 + V),
    # and the positions sum dt times that over the steps
    velocity = simulate("plank-drop", dt=DT, steps=200, tol="high")
    speed = float(np.max(np.linalg.norm(velocity.velocities, axis=2)))
    drift = velocity.n_steps * DT * VERIFY_FACTOR * EPS_HIGH * (1.0 + speed)  # 1.3e-6 m
    np.testing.assert_allclose(rigid.points, velocity.points, rtol=0.0, atol=drift)


def test_the_domino_row_falls_to_the_last() -> None:
    traj = simulate("domino-row", dt=DT, steps=300)  # 3 s: the last falls at about 2.4 s
    angles = np.stack([box_angles(traj, k) for k in range(DOMINO_COUNT)], axis=1)
    np.testing.assert_array_equal(angles[0, 1:], 0.0)  # all but the first start upright
    tipped = np.abs(angles) > math.pi / 4
    assert tipped[-1].all()  # every domino ends more than half-way down ...
    first_tipped = np.argmax(tipped, axis=0)
    assert np.all(np.diff(first_tipped) > 0)  # ... one after the other, as a row falls
    assert traj.metrics["verified"].all()


# ------------------------------------------------------------------ wrong sizes
_BOX = "[[boxes]]\ncenter = [0.0, 2.0]\n"

#: (case id, what follows the box's center, field, message)
BAD_SIZES = [
    ("negative-height", "size = [2.0, -0.5]", "boxes[0].size[1]", "must be positive, got -0.5"),
    ("zero-width", "size = [0.0, 0.5]", "boxes[0].size[0]", "must be positive, got 0.0"),
    ("scalar", "size = 2.0", "boxes[0].size", "expected a list of two numbers"),
    ("three", "size = [1.0, 2.0, 3.0]", "boxes[0].size", "expected a list of two numbers"),
    ("string", 'size = [1.0, "2"]', "boxes[0].size[1]", "expected a number, got str"),
    ("nan", "size = [nan, 1.0]", "boxes[0].size[0]", "must be finite"),
    ("too-long", "size = [2e6, 1.0]", "boxes[0].size[0]",
     "out of range: magnitude at most 1e+06 m"),
    ("too-thin", "size = [1.0, 1e-7]", "boxes[0].size[1]", "out of range: at least 1e-06 m"),
    ("unknown-key", "sise = [1.0, 1.0]", "boxes[0].sise", "unknown key 'sise'"),
    ("negative-mass", "mass = -1.0", "boxes[0].mass", "must be positive"),
]


@pytest.mark.parametrize(("text", "field", "message"),
                         [pytest.param(t, f, m, id=i) for i, t, f, m in BAD_SIZES])
def test_a_wrong_box_is_one_input_error_naming_file_and_field(
        tmp_path: Path, text: str, field: str, message: str,
        capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "plank.toml"
    path.write_text(f"{_BOX}{text}\n", encoding="utf-8")
    with pytest.raises(InputError) as caught:
        Scene.from_toml(path)
    assert caught.value.field == field
    assert str(caught.value) == f"{path}: {field}: {caught.value.reason}"
    assert message in caught.value.reason
    # through the command line: exit status 2 and that line, nothing else
    assert main(["simulate", str(path), "--steps", "1"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err == f"wuerfel-cvx: error: {caught.value}\n"


@pytest.mark.subprocess
def test_a_wrong_box_size_exits_2_in_a_real_process(tmp_path: Path) -> None:
    path = tmp_path / "plank.toml"
    path.write_text(f"{_BOX}size = [2.0, -0.5]\n", encoding="utf-8")
    result = subprocess.run([sys.executable, "-m", "wuerfel_cvx.cli", "simulate", str(path),
                             "--steps", "1"], capture_output=True, text=True, timeout=120,
                            check=False)
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr == (f"wuerfel-cvx: error: {path}: boxes[0].size[1]: "
                             "must be positive, got -0.5\n")


def test_a_box_built_in_code_is_checked_like_a_loaded_one() -> None:
    with pytest.raises(InputError) as caught:
        Scene("code", boxes=(Box(center=(0.0, 1.0), size=(1.0, -2.0)),))
    assert caught.value.field == "boxes[0].size[1]"
    with pytest.raises(InputError) as caught:
        Scene("code", boxes=(Box(center=(0.0, 1.0), size=2.0),))  # type: ignore[arg-type]
    assert caught.value.field == "boxes[0].size"
    assert "two numbers" in caught.value.reason
    with pytest.raises(InputError, match="expected a Box, got Square"):
        Scene("code", boxes=(Square(center=(0.0, 1.0)),))  # type: ignore[arg-type]
    with pytest.raises(InputError, match="at least one square or box"):
        Scene("empty", tables=(FLOOR,))
    longest = LIMITS["length"].largest
    Scene("long", boxes=(Box(center=(0.0, 1.0), size=(longest, 1.0)),))  # on the limit


# ------------------------------------------------------------------ overlaps
def test_overlap_is_found_at_a_planks_far_end() -> None:
    """Candidate pairs use the box's own half diagonal (2.06 m), not its height's."""
    plank = Box(center=(0.0, 1.0), size=(4.0, 0.5))
    far_end = Square(center=(2.3, 1.0), size=0.8)  # 0.1 m into the plank's end
    with pytest.raises(InputError, match=r"overlaps boxes\[0\] by 0\.1 m") as caught:
        Scene("ends", (far_end,), boxes=(plank,))
    assert caught.value.field == "squares[0]"
    with pytest.raises(InputError, match=r"overlaps boxes\[1\]") as caught:
        Scene("two", boxes=(plank, Box(center=(4.9, 1.0), size=(6.0, 0.2))))
    assert caught.value.field == "boxes[0]"
    with pytest.raises(InputError, match=r"overlaps tables\[0\]"):
        Scene("sunk", boxes=(Box(center=(0.0, 0.2), size=(2.0, 0.5)),), tables=(FLOOR,))
    Scene("apart", (Square(center=(2.5, 1.0), size=0.8),), boxes=(plank,))


# ------------------------------------------------------------------ generator and fuzzer
def test_generated_scenes_hold_boxes_of_random_aspect_ratio() -> None:
    scenes = [random_scene(np.random.default_rng(seed)) for seed in range(20)]
    boxes = [box for scene in scenes for box in scene.boxes]
    squares = [square for scene in scenes for square in scene.squares]
    assert len(boxes) > 10 and len(squares) > 10
    ratios = np.array([box.width / box.height for box in boxes])
    assert np.all((ratios >= ASPECT_RANGE[0]) & (ratios <= ASPECT_RANGE[1]))
    assert ratios.min() < 0.5 and ratios.max() > 2.0  # both ways, not just near 1


def test_fuzzed_box_files_never_crash_the_loader() -> None:
    seeds = [(name, data) for name, data in seed_files() if b"[[boxes]]" in data]
    assert {name for name, _ in seeds} == {"plank-drop", "domino-row"}
    result = run_fuzz(150, seed=17, step=False, seeds=seeds)
    assert result.crashes == []
    assert result.tried == 150 == result.accepted + result.rejected
    assert result.accepted >= 10 and result.rejected >= 75
