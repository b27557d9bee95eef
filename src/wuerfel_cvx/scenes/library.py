"""Named scenes, defined once and shared by tests, benchmarks and notebooks.

Each entry is a builder; families take a number after a dash (``stack-10``,
``pyramid-4``, ``rain-50``, ``heavy-on-light-1000``, ``spinning-pile-20``).  Every scene
has a floor whose top face is at ``y = 0``; unit squares unless stated otherwise
(``plank-drop`` and ``domino-row`` are boxes).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .analytic import ladder_scene, launched_box_scene, slope_scene
from .field import FIELD_SCENES
from .geometry import FloatArray
from .scene import Box, Scene, Square, Table

FLOOR = Table(center=(0.0, -0.5), size=(40.0, 1.0), angle=0.0)
"""The default table: 40 m wide, 1 m thick, top face at y = 0."""


@dataclass(frozen=True)
class SceneEntry:
    """A named scene or family of scenes in the library."""

    pattern: str
    """Name as shown to users; ``N`` stands for a positive integer."""
    description: str
    """One line on what the scene tests."""
    build: Callable[[int | None], Scene]
    """Builder; receives the family number or ``None``."""
    default_number: int | None = None
    """Number used when a family is named without one (``None``: required)."""


def _single_drop(_: int | None) -> Scene:
    return Scene("single-drop", (Square(center=(0.0, 2.0)),), (FLOOR,))


def _tilted_drop(_: int | None) -> Scene:
    return Scene("tilted-drop", (Square(center=(0.0, 2.0), angle=0.3),), (FLOOR,))


def _corner_drop(_: int | None) -> Scene:
    # 0.05 rad off balance: exactly 45 degrees would stay balanced on its corner forever
    # (frictionless and symmetric: an unstable equilibrium that exact arithmetic keeps).
    return Scene("corner-drop", (Square(center=(0.0, 2.0), angle=math.pi / 4 + 0.05),),
                 (FLOOR,))


def _resting_square(_: int | None) -> Scene:
    return Scene("resting-square", (Square(center=(0.0, 0.5)),), (FLOOR,))


def _spinning_flight(_: int | None) -> Scene:
    square = Square(center=(0.0, 10.0), angle=0.2, velocity=(1.5, 4.0), angular_velocity=3.0)
    return Scene("spinning-flight", (square,), ())


def _stack(n: int | None) -> Scene:
    count = _require(n, "stack")
    squares = tuple(Square(center=(0.0, 0.5 + k)) for k in range(count))
    return Scene(f"stack-{count}", squares, (FLOOR,))


def _pyramid(n: int | None) -> Scene:
    base = _require(n, "pyramid")
    pitch = 1.1  # 0.1 m between neighbours in a row: no corner meets a corner
    squares = []
    for row in range(base):
        count = base - row
        for i in range(count):
            squares.append(Square(center=((i - (count - 1) / 2) * pitch, 0.5 + row)))
    return Scene(f"pyramid-{base}", tuple(squares), (FLOOR,))


GRID_CELL = 1.6
"""Cell (m) of the grids of ``rain-N`` and ``spinning-pile-N``: wider than the largest
square's swept circle (diameter sqrt(2) m) with its jitter, so the squares start apart
from each other and from the walls, whatever their angle."""


def _walled_grid(count: int) -> tuple[int, float, tuple[Table, Table, Table]]:
    """Columns and width (m) of a grid of ``count`` cells, and its floor and two walls."""
    columns = max(3, math.ceil(math.sqrt(count)))
    rows = math.ceil(count / columns)
    width = columns * GRID_CELL
    height = rows * GRID_CELL + 2.0
    floor = Table(center=(0.0, -0.5), size=(width + 2.0, 1.0))
    left = Table(center=(-width / 2 - 0.5, height / 2), size=(1.0, height))
    right = Table(center=(width / 2 + 0.5, height / 2), size=(1.0, height))
    return columns, width, (floor, left, right)


def _cell_center(k: int, columns: int, width: float, jitter: FloatArray) -> tuple[float, float]:
    """Centre (m) of cell ``k`` of a :func:`_walled_grid`, moved by ``jitter`` (m).

    Cells are filled row by row, the lowest row's bottom 1 m above the floor.
    """
    row, col = divmod(k, columns)
    return (-width / 2 + (col + 0.5) * GRID_CELL + float(jitter[0]),
            1.0 + (row + 0.5) * GRID_CELL + float(jitter[1]))


def _rain(n: int | None) -> Scene:
    count = _require(n, "rain")
    rng = np.random.default_rng(20261122 + count)
    columns, width, tables = _walled_grid(count)
    squares = []
    for k in range(count):
        size = float(rng.uniform(0.6, 1.0))
        center = _cell_center(k, columns, width, rng.uniform(-0.05, 0.05, size=2))
        squares.append(Square(center=center, size=size, angle=float(rng.uniform(0, math.pi / 2)),
                              mass=size * size))
    return Scene(f"rain-{count}", tuple(squares), tables)


def _heavy_on_light(n: int | None) -> Scene:
    ratio = _require(n, "heavy-on-light")
    squares = (Square(center=(0.0, 0.5)), Square(center=(0.0, 1.5)),
               Square(center=(0.0, 2.5), mass=float(ratio)))
    name = "heavy-on-light" if ratio == 100 else f"heavy-on-light-{ratio}"
    return Scene(name, squares, (FLOOR,))


def _overlap_recovery(_: int | None) -> Scene:
    squares = (Square(center=(0.0, 0.5)), Square(center=(0.1, 1.25)))
    return Scene("overlap-recovery", squares, (FLOOR,), allow_overlap=True)


def _fast_drop(_: int | None) -> Scene:
    return Scene("fast-drop", (Square(center=(0.0, 3.0), angle=0.1, velocity=(0.0, -40.0)),),
                 (FLOOR,))


def _two_corner_landing(_: int | None) -> Scene:
    # A 0.6 m square falls flat onto the middle of a resting unit square: its two lower
    # corners reach the same edge at the same instant (two simultaneous, redundant contacts).
    squares = (Square(center=(0.0, 0.5)), Square(center=(0.0, 1.8), size=0.6, mass=0.36))
    return Scene("two-corner-landing", squares, (FLOOR,))


def _edge_end_landing(_: int | None) -> Scene:
    # Exactly aligned: each lower corner of the falling square lands on an end of the
    # resting square's top edge (alpha = 0 or 1, where the edge rule's sectors meet).
    squares = (Square(center=(0.0, 0.5)), Square(center=(0.0, 2.0)))
    return Scene("edge-end-landing", squares, (FLOOR,))


def _wall_contact(_: int | None) -> Scene:
    # Sliding (frictionless) at 3 m/s into a wall: the contact is on a vertical edge.
    wall = Table(center=(2.5, 1.5), size=(1.0, 3.0))
    square = Square(center=(0.0, 0.5), angle=0.0, velocity=(3.0, 0.0))
    return Scene("wall-contact", (square,), (FLOOR, wall))


PLANK_SIZE = (2.0, 0.5)
"""Width and height (m) of the plank of ``plank-drop``."""
DOMINO_SIZE = (0.1, 1.0)
"""Width and height (m) of each domino of ``domino-row``."""
DOMINO_PITCH = 0.45
"""Distance (m) between neighbouring dominoes' centres: less than their height, so a
falling one reaches the next."""
DOMINO_COUNT = 6
"""Dominoes in ``domino-row``."""
CURB_SIZE = 0.05
"""Side (m) of the square curb in front of each domino but the first, on the floor."""
CURB_GAP = 1e-3
"""Gap (m) between a domino's front face and its curb."""


def _plank_drop(_: int | None) -> Scene:
    # Lowest corner 1.5 - (1.0 sin 0.3 + 0.25 cos 0.3) = 0.97 m above the floor; it lands
    # on that corner and tips onto a long side, coming to rest flat at y = 0.25 m.
    plank = Box(center=(0.0, 1.5), size=PLANK_SIZE, angle=0.3)
    return Scene("plank-drop", boxes=(plank,), tables=(FLOOR,))


def _domino_row(_: int | None) -> Scene:
    # Frictionless, a domino pushed at its top would mostly slide forward; a low curb just
    # in front of each base (after the first) blocks the slide, so it tips over the curb.
    width, height = DOMINO_SIZE
    # the first leans 0.2 rad clockwise, towards the others; at the same centre height
    # as the rest, its lowest corner is (1 - cos 0.2) / 2 - 0.05 sin 0.2 = 33 um up
    dominoes = [Box(center=(0.0, height / 2), size=DOMINO_SIZE, angle=-0.2)]
    curbs = []
    for k in range(1, DOMINO_COUNT):
        dominoes.append(Box(center=(k * DOMINO_PITCH, height / 2), size=DOMINO_SIZE))
        # to the nanometre, so that examples/domino-row.toml states the same numbers
        middle = round(k * DOMINO_PITCH + width / 2 + CURB_GAP + CURB_SIZE / 2, 9)
        curbs.append(Table(center=(middle, CURB_SIZE / 2), size=(CURB_SIZE, CURB_SIZE)))
    return Scene("domino-row", boxes=tuple(dominoes), tables=(FLOOR, *curbs))


SPIN_RANGE = (8.0, 15.0)
"""Spin magnitudes (rad/s) of the squares of ``spinning-pile-N``; the sign is random."""
SPINNING_PILE_SIZES = (0.5, 1.0)
"""Side lengths (m) of the squares of ``spinning-pile-N``."""


def _spinning_pile(n: int | None) -> Scene:
    # A rain of squares that spin at 8 to 15 rad/s: in one step of 0.01 s a square turns
    # by 0.08 to 0.15 rad, and a corner at r = 0.35 to 0.71 m from its centre leaves the
    # line its velocity predicts by up to (omega dt)^2 r / 2 = 1 to 8 mm, the error of
    # contacts linearised in the velocities.  Frictionless, nothing slows the spins
    # before the squares meet the floor, the walls and each other.
    count = _require(n, "spinning-pile")
    rng = np.random.default_rng(20261201 + count)
    columns, width, tables = _walled_grid(count)
    squares = []
    for k in range(count):
        size = float(rng.uniform(*SPINNING_PILE_SIZES))
        center = _cell_center(k, columns, width, rng.uniform(-0.05, 0.05, size=2))
        spin = float(rng.uniform(*SPIN_RANGE)) * float(rng.choice((-1.0, 1.0)))
        squares.append(Square(center=center, size=size, angle=float(rng.uniform(0, math.pi / 2)),
                              mass=size * size, angular_velocity=spin))
    return Scene(f"spinning-pile-{count}", tuple(squares), tables)


# Two squares as the property checks found them: the upper one stands on the lower with
# a side face flush to the lower one's and is tilted by under 1e-3 rad, so that at that
# side a corner of each lies inside the other.  Each such corner is 3e-8 to 4e-7 m inside
# the other square's side face but 2e-4 to 5e-4 m beyond its top (or bottom) face: the
# two squares overlap by that much (the separating-axis depth), which is why the scenes
# allow overlap, while the corners' own depth, the penetration metric, is the side-face
# distance.  Both slide together on the frictionless floor.  Each is the state of the
# pinned run (tests/test_properties.py, 200 steps of 0.01 s with CLARABEL at `default`)
# one step before its energy first rose by over 1e-5 J, as a rigid fit of the pair's
# corners: centre, angle (edge from corner 0 to 1), centre velocity and spin.
def _corner_overlap(_: int | None) -> Scene:
    # corner-on-corner (hypothesis), bodies 3 and 4, after 162 steps: two equal squares
    side, mass = 0.2558948352610064, 2.001306845030394
    lower = Square(center=(-4.286908386868901, 0.12794741764030762), size=side,
                   angle=-2.356657542603048e-11, mass=mass,
                   velocity=(-3.6686453603102387, -8.480040555595423e-10),
                   angular_velocity=2.115271348572556e-09)
    upper = Square(center=(-4.2868107069602726, 0.383744536188964), size=side,
                   angle=-0.0007634379550096703, mass=mass,
                   velocity=(-3.669730708225151, 0.001086209007331871),
                   angular_velocity=0.008482766167282975)
    return Scene("corner-overlap", (lower, upper), (FLOOR,), allow_overlap=True)


def _corner_overlap_wedged(_: int | None) -> Scene:
    # wedged-corner (run_property_sweep(200, seed=100), scene 186), bodies 2 and 4, after
    # 113 steps: a heavy 0.56 m square (6.5 kg) on a light 0.69 m one (1.7 kg)
    lower = Square(center=(-2.4579960978910957, 0.3432238974190768), size=0.6864477947718535,
                   angle=-5.348948636628146e-11, mass=1.7057198309492716,
                   velocity=(0.6402940134933637, 3.022853949483767e-09),
                   angular_velocity=-5.897104130841979e-09)
    upper = Square(center=(-2.3947114833611782, 0.9663869678086059), size=0.5603781208738501,
                   angle=1.5699048660875181, mass=6.547215546607483,
                   velocity=(0.6375152669240375, 0.0027677586318652298),
                   angular_velocity=0.009917391911289172)
    return Scene("corner-overlap-wedged", (lower, upper), (FLOOR,), allow_overlap=True)


ROW_COUNT = 5
"""Squares in ``square-row`` and ``pushed-row``."""


def _square_row(_: int | None) -> Scene:
    squares = tuple(Square(center=(k - (ROW_COUNT - 1) / 2, 0.5)) for k in range(ROW_COUNT))
    return Scene("square-row", squares, (FLOOR,))


def _pushed_row(_: int | None) -> Scene:
    first = Square(center=(-(ROW_COUNT + 1) / 2, 0.5), velocity=(1.0, 0.0))
    rest = tuple(Square(center=(k - (ROW_COUNT - 3) / 2, 0.5)) for k in range(ROW_COUNT - 1))
    return Scene("pushed-row", (first, *rest), (FLOOR,))


def _inelastic_impact(_: int | None) -> Scene:
    moving = Square(center=(-1.5, 0.5), velocity=(2.0, 0.0))
    return Scene("inelastic-impact", (moving, Square(center=(0.0, 0.5))), (FLOOR,))


def _require(n: int | None, family: str) -> int:
    if n is None or n < 1:
        raise InputError(f"'{family}-N' needs a positive integer N", source=family)
    return n


ENTRIES: tuple[SceneEntry, ...] = (
    SceneEntry("single-drop", "a unit square dropped flat from y = 2 m", _single_drop),
    SceneEntry("tilted-drop", "a unit square dropped from y = 2 m at 0.3 rad", _tilted_drop),
    SceneEntry("corner-drop", "a unit square dropped corner first, 0.05 rad off balance",
               _corner_drop),
    SceneEntry("resting-square", "a unit square resting on the table", _resting_square),
    SceneEntry("spinning-flight", "a spinning square in free flight, no table",
               _spinning_flight),
    SceneEntry("stack-N", "N unit squares stacked exactly, at rest", _stack, 10),
    SceneEntry("pyramid-N", "a pyramid with N squares in its base, 0.1 m gaps", _pyramid, 4),
    SceneEntry("rain-N", "N squares of random size and angle falling into a box of tables",
               _rain, 20),
    SceneEntry("heavy-on-light-N", "a square of mass N kg on two 1 kg squares (N = 100)",
               _heavy_on_light, 100),
    SceneEntry("overlap-recovery", "a square starting 25 % overlapped with the one below",
               _overlap_recovery),
    SceneEntry("fast-drop", "a square at 40 m/s: one 1/60 s step moves 0.67 side lengths",
               _fast_drop),
    SceneEntry("two-corner-landing", "a 0.6 m square lands flat on a resting one: two "
               "corners reach an edge at once", _two_corner_landing),
    SceneEntry("edge-end-landing", "a square lands exactly aligned on another: corners "
               "meet edge ends", _edge_end_landing),
    SceneEntry("wall-contact", "a square slides at 3 m/s into a wall: contact on a vertical "
               "edge", _wall_contact),
    SceneEntry("plank-drop", "a 2 x 0.5 m plank dropped from y = 1.5 m at 0.3 rad: lands on "
               "a corner, settles flat", _plank_drop),
    SceneEntry("domino-row", "six 0.1 x 1 m dominoes, curbs at their feet; the first, "
               "tipped 0.2 rad, knocks them over", _domino_row),
    SceneEntry("spinning-pile-N", "N squares of mixed size spinning at 8-15 rad/s, falling "
               "into a box of tables", _spinning_pile, 20),
    SceneEntry("corner-overlap", "two equal squares sliding stacked, a corner of each 4e-8 "
               "and 1.1e-7 m inside the other (found by the property tests)", _corner_overlap),
    SceneEntry("corner-overlap-wedged", "a heavy square on a light one, sliding, a corner of "
               "each 1.1e-7 and 3.3e-7 m inside the other (found by a property sweep)",
               _corner_overlap_wedged),
    SceneEntry("friction-slope", "a square on a table tilted 0.4 rad, mu 0.3: slides with "
               "g (sin - mu cos)", lambda _: slope_scene()),
    SceneEntry("friction-slide", "a square launched at 3 m/s on a table, mu 0.5: stops after "
               "v0^2 / (2 mu g)", lambda _: launched_box_scene()),
    SceneEntry("ladder", "a 2 x 0.1 m plank leaning at 60 degrees on a frictionless wall, "
               "floor mu 0.3 (stands above 0.264)", lambda _: ladder_scene()),
    SceneEntry("square-row", "five unit squares side by side at rest on a frictionless "
               "floor: contacts that carry no load", _square_row),
    SceneEntry("pushed-row", "a square at 1 m/s, 0.5 m from a resting row of four, "
               "frictionless: the push travels down the row", _pushed_row),
    SceneEntry("inelastic-impact", "a square at 2 m/s hits a resting one on a frictionless "
               "floor: they move on together", _inelastic_impact),
    # the field's scenes, from Solver2D and Box2D v3 (wuerfel_cvx.scenes.field)
    *(SceneEntry(*row) for row in FIELD_SCENES),
)

_NAME = re.compile(r"^(?P<base>[a-z][a-z-]*?)(?:-(?P<number>\d+))?$")


def scene_names() -> list[str]:
    """The library's names as shown to users (``N`` marks a family number)."""
    return [entry.pattern for entry in ENTRIES]


def named_scene(name: str) -> Scene:
    """Build a library scene by name, e.g. ``"stack-10"``; raises :class:`InputError`."""
    match = _NAME.match(name.strip().lower())
    if match:
        base, number = match["base"], match["number"]
        for entry in ENTRIES:
            family = entry.pattern.removesuffix("-N")
            is_family = entry.pattern.endswith("-N")
            if is_family and base == family:
                value = int(number) if number is not None else entry.default_number
                return entry.build(value)
            if not is_family and number is None and base == entry.pattern:
                return entry.build(None)
            if not is_family and number is not None and f"{base}-{number}" == entry.pattern:
                return entry.build(None)
    raise InputError(f"unknown scene '{name}' (named scenes: {', '.join(scene_names())}; "
                     "or give a .toml path)", source=name)
