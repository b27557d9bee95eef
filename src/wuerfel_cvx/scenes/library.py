"""Named scenes, defined once and shared by tests, benchmarks and notebooks.

Each entry is a builder; families take a number after a dash (``stack-10``,
``pyramid-4``, ``rain-50``, ``heavy-on-light-1000``, ``spinning-pile-20``).  Every scene
has a floor whose top face is at ``y = 0``; unit squares unless stated otherwise
(``plank-drop`` and ``domino-row`` are boxes).

The library's own scenes come first, then the field's benchmark scenes (Solver2D's and
Box2D v3's samples in this package's bodies), then scenes with friction whose motion is
known in closed form; last the registry of names (:data:`ENTRIES`, :func:`named_scene`).

**The field's scenes.**  Each is translated from its definition in Erin Catto's public
repositories (``erincatto/solver2d`` at commit d178a56, ``erincatto/box2d`` at commit
617d32a):

================================  =========================================================
``vertical-stack``                solver2d ``samples/collection/sample_contact.cpp``,
                                  ``VerticalStack`` (15 boxes, +-0.01 m offsets, mu 0.3)
``field-pyramid-N``               solver2d ``sample_contact.cpp``, ``Pyramid`` (base 20 in
                                  its debug build, 100 in release; here N, default 10)
``large-pyramid``                 box2d ``shared/benchmarks.c``, ``CreateLargePyramid``
                                  (base 100, 5050 boxes)
``friction-ramps``                solver2d ``sample_contact.cpp``, ``FrictionRamp``; the
                                  same scene is box2d ``samples/sample_shapes.cpp``,
                                  ``Friction``
``high-mass-ratio-1``             solver2d ``sample_contact.cpp``, ``HighMassRatio1``
``high-mass-ratio-2``             solver2d ``sample_contact.cpp``, ``HighMassRatio2``
``overlap-recovery-friction``     solver2d ``sample_contact.cpp``, ``OverlapRecovery``
``card-house``                    solver2d ``sample_contact.cpp`` and box2d
                                  ``samples/sample_stacking.cpp``, ``CardHouse`` (from PEEL)
``double-domino``                 solver2d ``sample_contact.cpp`` and box2d
                                  ``sample_stacking.cpp``, ``DoubleDomino``
``tilted-stack``                  box2d ``samples/sample_stacking.cpp``, ``TiltedStack``
================================  =========================================================

Positions, sizes, angles and friction coefficients are the sources' own (a Box2D
``MakeBox(hx, hy)`` takes half extents: it is a box of ``2 hx`` by ``2 hy`` here).  Where
a source leaves a shape's friction at its default, it is Box2D's default, 0.6
(:data:`BOX2D_DEFAULT_FRICTION`), grounds included; a contact's coefficient is then
``sqrt(mu_a mu_b)`` in both.  Deliberate differences:

- Gravity is this package's default, 9.81 m/s^2 (:data:`~wuerfel_cvx.scenes.scene.DEFAULT_GRAVITY`);
  Box2D and Solver2D use 10 m/s^2.
- Mass is Box2D's density times area (density 1 kg/m^2 unless the source sets another).
  The rotational inertia is not Box2D's: a body here is 4 corner masses, so a ``w`` by
  ``h`` box has ``I = m (w^2 + h^2) / 4`` (``m s^2 / 2`` for a square of side ``s``), three
  times a solid box's ``m (w^2 + h^2) / 12``.
- A ground segment (Box2D's ``b2Segment``) is a table 1 m thick with its top face along the
  segment; a ground box is the same box as a table.
- Box2D v3's rounded boxes (``b2MakeRoundedBox(0.45, 0.45, 0.05)`` in ``tilted-stack``) are
  sharp unit squares of mass 1 kg (the rounded box's area is 0.998 m^2).
- ``card-house``: the source puts the first floor's card centres at 0.18 m, so that a
  tilted card's lowest corner is 1.7 mm below the ground; here the whole house is raised
  by that amount (:func:`card_house_lift`), so those corners touch the ground exactly.
  The source's flat cards (0.4 m, 0.35 m apart on one floor) overlap their neighbours by
  5 cm end to end; here they are 0.35 m long, centred between the tops they bridge, and
  touch end to end (:data:`FLAT_CARD_SIZE`).
- ``vertical-stack`` is Solver2D's (15 boxes 0.1 m apart); Box2D v3's ``VerticalStack``
  is 12 rounded boxes that touch.  Its ground has the default 0.6, so a box's contact
  with it has ``sqrt(0.3 * 0.6) = 0.42``.  Likewise the ramps of ``friction-ramps`` have
  0.2, so their boxes' contacts have ``sqrt(0.2 mu)``.
- ``field-pyramid-N`` of a base over 190 gets a ground 10 m wider than the base.
- ``double-domino``: Box2D gives the first domino a linear impulse of 0.2 N s at its top;
  here it starts with the velocity and spin that impulse gives a body of this package's
  inertia (:func:`impulse_velocity`).
- The Solver2D pyramid's and the large pyramid's boxes touch their neighbours exactly
  (this library's ``pyramid-N`` keeps 0.1 m between them).

**Scenes with friction whose motion is known in closed form.**  Each builder takes the
parameters its formula needs and is shared by the tests, the notebook and the library
(``friction-slope``, ``friction-slide`` and ``ladder`` with the defaults below).  Unit
squares of 1 kg unless stated; gravity 9.81 m/s^2 down; a contact's coefficient is
``sqrt(mu_a mu_b)``, so a body and its table given the same ``friction`` meet with that
coefficient.

``slope_scene(angle, friction)``
    A square resting on a 12 m table tilted by ``angle`` (rad, 0 to 1), its lower face on
    the slope at :func:`slope_origin`, 8 m of slope below it, above the floor.  It slides
    down the slope with ``a = g (sin angle - mu cos angle)`` when ``mu < tan angle`` and
    stays put otherwise.
``launched_box_scene(speed, friction)``
    A square on a flat table, launched sideways at ``speed`` (m/s).  It stops after
    ``v0^2 / (2 mu g)`` (m), at time ``v0 / (mu g)`` (s).
``ladder_scene(friction, angle)``
    A 2 x 0.1 m plank leaning at ``angle`` (rad, from the floor) against a frictionless
    wall, its lowest corner on the floor and its rightmost corner on the wall.  Statics
    (three unknown forces, three equations) let it stand exactly when the floor's
    coefficient is at least :func:`ladder_static_friction`: the horizontal offset of its
    centre from the foot over the height of the wall contact above the foot.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from .geometry import FloatArray, rectangle_corners
from .scene import Box, Scene, Square, Table, Vec2

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


# ---------------------------------------------------------------------- the field's scenes
BOX2D_DEFAULT_FRICTION = 0.6
"""Friction coefficient (1) of a Box2D v3 or Solver2D shape left at its default."""

GROUND_BOX = Table(center=(0.0, -1.0), size=(200.0, 2.0), friction=BOX2D_DEFAULT_FRICTION)
"""Solver2D's and Box2D's ground box, ``MakeBox(100, 1)`` at ``(0, -1)``: top face at y = 0."""


def segment_ground(half_width: float, friction: float) -> Table:
    """A ground segment from ``-half_width`` to ``half_width`` (m) on y = 0, as a 1 m table."""
    return Table(center=(0.0, -0.5), size=(2.0 * half_width, 1.0), friction=friction)


# --------------------------------------------------------------------- stacks
VERTICAL_STACK_COUNT = 15
VERTICAL_STACK_OFFSET = 0.01
"""Horizontal offset (m) of each box of ``vertical-stack``, alternating -, +, -, ..."""
VERTICAL_STACK_FRICTION = 0.3


def vertical_stack(_: int | None = None) -> Scene:
    """Solver2D's vertical stack: 15 unit boxes 0.1 m apart, offset by +-0.01 m, mu 0.3."""
    boxes = tuple(
        Square(center=(-VERTICAL_STACK_OFFSET if i % 2 == 0 else VERTICAL_STACK_OFFSET,
                       0.55 + 1.1 * i), friction=VERTICAL_STACK_FRICTION)
        for i in range(VERTICAL_STACK_COUNT))
    return Scene("vertical-stack", boxes, (GROUND_BOX,))


TILTED_STACK_ROWS = 10
TILTED_STACK_COLUMNS = 10
TILTED_STACK_SHIFT = 0.2
"""Horizontal shift (m) of each box of a ``tilted-stack`` column against the one below."""
TILTED_STACK_FRICTION = 0.3


def tilted_stack(_: int | None = None) -> Scene:
    """Box2D's tilted stack: 10 columns 5 m apart of 10 unit boxes, each 0.2 m further right."""
    pitch = 5.0
    root = -0.5 * pitch * (TILTED_STACK_COLUMNS - 1.0)
    boxes = tuple(
        Square(center=(root + j * pitch + TILTED_STACK_SHIFT * i, 0.5 + i),
               friction=TILTED_STACK_FRICTION)
        for j in range(TILTED_STACK_COLUMNS) for i in range(TILTED_STACK_ROWS))
    # Box2D's ground here is MakeBox(1000, 1): 2 km wide
    ground = Table(center=(0.0, -1.0), size=(2000.0, 2.0), friction=BOX2D_DEFAULT_FRICTION)
    return Scene("tilted-stack", boxes, (ground,))


# --------------------------------------------------------------------- pyramids
PYRAMID_FRICTION = BOX2D_DEFAULT_FRICTION
LARGE_PYRAMID_BASE = 100


def pyramid_squares(base: int, side: float, friction: float,
                    x_offset: float = 0.0) -> list[Square]:
    """Solver2D's and Box2D's pyramid: rows of touching squares, each row half a side in.

    Row ``i`` (from 0 at the bottom) holds ``base - i`` squares of side ``side`` (m) and
    mass ``side^2`` (density 1), centred at ``y = (i + 1/2) side``; the base is centred
    on ``x_offset`` (m).
    """
    half = side / 2.0
    squares = []
    for i in range(base):
        for j in range(i, base):
            x = (i + 1.0) * half + 2.0 * (j - i) * half - half * base + x_offset
            squares.append(Square(center=(x, (2.0 * i + 1.0) * half), size=side,
                                  mass=side * side, friction=friction))
    return squares


def _pyramid_scene(name: str, base: int) -> Scene:
    ground = GROUND_BOX
    if base > GROUND_BOX.size[0] - 10:  # keep 5 m of ground beyond each end of the base
        ground = Table(center=GROUND_BOX.center, size=(base + 10.0, GROUND_BOX.size[1]),
                       friction=GROUND_BOX.friction)
    return Scene(name, tuple(pyramid_squares(base, 1.0, PYRAMID_FRICTION)), (ground,))


def field_pyramid(n: int | None) -> Scene:
    """Solver2D's pyramid with ``n`` unit boxes in its base, touching, mu 0.6."""
    if n is None or n < 1:
        raise InputError("'field-pyramid-N' needs a positive integer N",
                         source="field-pyramid")
    return _pyramid_scene(f"field-pyramid-{n}", n)


def large_pyramid(_: int | None = None) -> Scene:
    """Box2D's ``large_pyramid`` benchmark: base 100, 5050 touching unit boxes, mu 0.6."""
    return _pyramid_scene("large-pyramid", LARGE_PYRAMID_BASE)


HIGH_MASS_RATIO_1_FRICTION = 0.5
HIGH_MASS_RATIO_1_APEX_DENSITY = (100.0, 200.0, 300.0)
"""Density (kg/m^2) of the top box of each pyramid of ``high-mass-ratio-1``; the others 1."""
HIGH_MASS_RATIO_1_APEX_LIFT = 2.0
"""Height (m) above its place in the pyramid at which each top box starts."""


def high_mass_ratio_1(_: int | None = None) -> Scene:
    """Solver2D's high mass ratio 1: three pyramids of 2 m boxes, tops 100-300 times heavier."""
    side, base = 2.0, 10
    squares = []
    for j, density in enumerate(HIGH_MASS_RATIO_1_APEX_DENSITY):
        # Solver2D's offset is -20 + 2 (count + 1) j with count = 10; each base is centred
        # half a box (1 m) left of it
        pyramid = pyramid_squares(base, side, HIGH_MASS_RATIO_1_FRICTION,
                                  x_offset=-20.0 + 2.0 * (base + 1.0) * j - side / 2.0)
        apex = pyramid[-1]
        x, y = apex.center
        pyramid[-1] = Square(center=(x, y + HIGH_MASS_RATIO_1_APEX_LIFT), size=side,
                             mass=density * side * side, friction=HIGH_MASS_RATIO_1_FRICTION)
        squares += pyramid
    ground = segment_ground(66.0, HIGH_MASS_RATIO_1_FRICTION)
    return Scene("high-mass-ratio-1", tuple(squares), (ground,))


HIGH_MASS_RATIO_2_BIG_SIDE = 20.0
"""Side (m) of the big box of ``high-mass-ratio-2``; the small ones are 1 m."""


def high_mass_ratio_2(_: int | None = None) -> Scene:
    """Solver2D's high mass ratio 2: a 20 m box (400 kg) falls 15 m onto two 1 m boxes."""
    mu = BOX2D_DEFAULT_FRICTION
    big = HIGH_MASS_RATIO_2_BIG_SIDE
    squares = (Square(center=(-9.0, 0.5), friction=mu), Square(center=(9.0, 0.5), friction=mu),
               Square(center=(0.0, big / 2.0 + 16.0), size=big, mass=big * big, friction=mu))
    return Scene("high-mass-ratio-2", squares, (segment_ground(20.0, mu),))


OVERLAP_RECOVERY_BASE = 4
OVERLAP_RECOVERY_FRACTION = 0.25
"""Overlap of neighbouring boxes, as a fraction of their side (Solver2D's ``overlap``)."""


def overlap_recovery_friction(_: int | None = None) -> Scene:
    """Solver2D's overlap recovery: a pyramid of 4 unit boxes overlapping by 25 %, mu 0.6.

    Neighbours in a row and in adjacent rows are ``0.75`` m apart, so each pair overlaps
    by 0.25 m (the separating-axis depth); the bottom row touches the ground.
    """
    mu = BOX2D_DEFAULT_FRICTION
    extent, base = 0.5, OVERLAP_RECOVERY_BASE
    pitch = 2.0 * (1.0 - OVERLAP_RECOVERY_FRACTION) * extent
    squares, y = [], extent
    for i in range(base):
        x = (1.0 - OVERLAP_RECOVERY_FRACTION) * extent * (i - base)
        for _ in range(i, base):
            squares.append(Square(center=(x, y), friction=mu))
            x += pitch
        y += pitch
    return Scene("overlap-recovery-friction", tuple(squares), (segment_ground(40.0, mu),),
                 allow_overlap=True)


# --------------------------------------------------------------------- friction ramps
RAMP_FRICTION = 0.2
"""Friction (1) of the ramps, stops and ground of ``friction-ramps``."""
RAMP_BOX_FRICTION = (0.75, 0.5, 0.35, 0.1, 0.0)
RAMP_BOX_DENSITY = 25.0
"""Density (kg/m^2) of the ramps' unit boxes: 25 kg each."""
RAMP_ANGLE = 0.25
"""Tilt (rad) of each ramp, alternately clockwise and counter-clockwise."""
RAMPS: tuple[tuple[Vec2, Vec2, float], ...] = (
    ((-4.0, 22.0), (26.0, 0.5), -RAMP_ANGLE),
    ((10.5, 19.0), (0.5, 2.0), 0.0),  # a stop at the lower end of the first ramp
    ((4.0, 14.0), (26.0, 0.5), RAMP_ANGLE),
    ((-10.5, 11.0), (0.5, 2.0), 0.0),
    ((-4.0, 6.0), (26.0, 0.5), -RAMP_ANGLE),
)
"""Centre (m), size (m) and angle (rad) of each ramp and stop, Solver2D's offset boxes."""


def friction_ramps(_: int | None = None) -> Scene:
    """Solver2D's friction ramp: five unit boxes, mu 0.75 to 0, dropped onto zigzag ramps.

    The ramps are tilted by 0.25 rad and have mu 0.2, so a contact's coefficient is
    ``sqrt(0.2 mu)``: 0.39, 0.32, 0.26, 0.14 and 0, against ``tan 0.25 = 0.255``.
    """
    tables = (segment_ground(40.0, RAMP_FRICTION),
              *(Table(center=c, size=s, angle=a, friction=RAMP_FRICTION) for c, s, a in RAMPS))
    boxes = tuple(Square(center=(-15.0 + 4.0 * i, 28.0), mass=RAMP_BOX_DENSITY, friction=mu)
                  for i, mu in enumerate(RAMP_BOX_FRICTION))
    return Scene("friction-ramps", boxes, tables)


# --------------------------------------------------------------------- cards and dominoes
CARD_SIZE = (0.002, 0.4)
"""Width (thickness) and height (m) of a card of ``card-house``."""
CARD_FRICTION = 0.7
CARD_TILT = math.radians(25.0)
"""Tilt (rad) of the leaning cards, alternately clockwise and counter-clockwise."""
CARD_HOUSE_FLOORS = 5
CARD_PAIR_PITCH = 0.35
"""Distance (m) between neighbouring pairs of leaning cards; a pair's cards are half that
apart at their feet."""
FLAT_CARD_SIZE = (CARD_SIZE[0], CARD_PAIR_PITCH)
"""Thickness and length (m) of the flat cards: one pitch, so that neighbours touch end to
end over an apex (the source's 0.4 m cards overlap by 5 cm there)."""


def card_house_lift() -> float:
    """Height (m) the house is raised above the source's so its lowest corners touch y = 0.

    The source centres the first floor's tilted cards at ``0.2 - 0.02`` m; their lowest
    corners are ``(h/2) cos 25 deg + (w/2) sin 25 deg`` below their centres.
    """
    width, height = CARD_SIZE
    reach = height / 2 * math.cos(CARD_TILT) + width / 2 * math.sin(CARD_TILT)
    return reach - (height / 2 - 0.02)


def card_house(_: int | None = None) -> Scene:
    """PEEL's card house (Solver2D, Box2D): five floors of leaning card pairs, 40 cards.

    Each floor has pairs of cards leaning towards each other at +-25 degrees (their tops
    6 mm apart) and a flat card bridging each two neighbouring pairs' tops; each floor
    above has one pair fewer.  The source's flat cards are 0.4 m long and centred 0.25 m
    right of a pair's left card, so that neighbours overlap by 5 cm; here they are
    0.35 m long, centred between the tops they bridge, and touch end to end.
    """
    half_height = CARD_SIZE[1] / 2
    mass = CARD_SIZE[0] * CARD_SIZE[1]  # density 1
    cards = []

    def card(x: float, y: float, angle: float) -> None:
        cards.append(Box(center=(x, y), size=CARD_SIZE, angle=angle, mass=mass,
                         friction=CARD_FRICTION))

    def flat(x: float, y: float) -> None:
        cards.append(Box(center=(x, y), size=FLAT_CARD_SIZE, angle=0.5 * math.pi,
                         mass=FLAT_CARD_SIZE[0] * FLAT_CARD_SIZE[1], friction=CARD_FRICTION))

    z0, y = 0.0, half_height - 0.02 + card_house_lift()
    for pairs in range(CARD_HOUSE_FLOORS, 0, -1):
        z = z0
        for i in range(pairs):
            if i != pairs - 1:  # from this pair's apex (z + pitch / 4) to the next one's
                flat(z + 0.75 * CARD_PAIR_PITCH, y + half_height - 0.015)
            card(z, y, -CARD_TILT)
            card(z + CARD_PAIR_PITCH / 2, y, CARD_TILT)
            z += CARD_PAIR_PITCH
        y += 2.0 * half_height - 0.03
        z0 += CARD_PAIR_PITCH / 2
    ground = Table(center=(0.0, -2.0), size=(80.0, 4.0), friction=CARD_FRICTION)
    return Scene("card-house", boxes=tuple(cards), tables=(ground,))


DOUBLE_DOMINO_SIZE = (0.25, 1.0)
"""Width and height (m) of each domino of ``double-domino``."""
DOUBLE_DOMINO_COUNT = 15
DOUBLE_DOMINO_FRICTION = 0.6
DOUBLE_DOMINO_IMPULSE = (0.2, 0.0)
"""Linear impulse (N s) Box2D gives the first domino, at the middle of its top face."""


def impulse_velocity(box: Box, impulse: Vec2, point: Vec2) -> tuple[Vec2, float]:
    """Velocity (m/s) and spin (rad/s) of ``box``, at rest, after ``impulse`` (N s) at ``point``.

    ``v = J / m`` and ``omega = (r x J) / I`` with ``r`` from the centre to ``point`` and
    this package's inertia ``I = m (w^2 + h^2) / 4`` of 4 corner masses.
    """
    inertia = box.mass * (box.width ** 2 + box.height ** 2) / 4.0
    r = (point[0] - box.center[0], point[1] - box.center[1])
    torque = r[0] * impulse[1] - r[1] * impulse[0]
    return (impulse[0] / box.mass, impulse[1] / box.mass), torque / inertia


def double_domino(_: int | None = None) -> Scene:
    """Solver2D's and Box2D's double domino: 15 dominoes 1 m apart, the first one pushed."""
    width, height = DOUBLE_DOMINO_SIZE
    mass = width * height  # density 1
    dominoes = []
    for i in range(DOUBLE_DOMINO_COUNT):
        x = -0.5 * DOUBLE_DOMINO_COUNT + i
        domino = Box(center=(x, height / 2), size=DOUBLE_DOMINO_SIZE, mass=mass,
                     friction=DOUBLE_DOMINO_FRICTION)
        if i == 0:
            velocity, spin = impulse_velocity(domino, DOUBLE_DOMINO_IMPULSE, (x, height))
            domino = Box(center=domino.center, size=domino.size, mass=mass, velocity=velocity,
                         angular_velocity=spin, friction=DOUBLE_DOMINO_FRICTION)
        dominoes.append(domino)
    return Scene("double-domino", boxes=tuple(dominoes), tables=(GROUND_BOX,))


# --------------------------------------------------------------------- the library's rows
FIELD_SCENES: tuple[tuple[str, str, Callable[[int | None], Scene], int | None], ...] = (
    ("vertical-stack", "Solver2D: 15 unit boxes 0.1 m apart, +-0.01 m offsets, mu 0.3",
     vertical_stack, None),
    ("field-pyramid-N", "Solver2D: a pyramid of touching unit boxes, N in its base, mu 0.6",
     field_pyramid, 10),
    ("large-pyramid", "Box2D's large_pyramid benchmark: base 100, 5050 touching unit boxes, "
     "mu 0.6", large_pyramid, None),
    ("friction-ramps", "Solver2D/Box2D: five boxes, mu 0.75 to 0, on 0.25 rad ramps of mu 0.2",
     friction_ramps, None),
    ("high-mass-ratio-1", "Solver2D: three pyramids of 2 m boxes, tops 100, 200, 300 times "
     "heavier", high_mass_ratio_1, None),
    ("high-mass-ratio-2", "Solver2D: a 20 m box of 400 kg falls onto two 1 m boxes of 1 kg",
     high_mass_ratio_2, None),
    ("overlap-recovery-friction", "Solver2D: a 4-base pyramid of unit boxes overlapping by "
     "25 %, mu 0.6", overlap_recovery_friction, None),
    ("card-house", "PEEL/Box2D: 40 cards 2 mm thick in five floors (0.4 m leaning, 0.35 m "
     "flat), mu 0.7", card_house,
     None),
    ("double-domino", "Solver2D/Box2D: 15 dominoes 0.25 x 1 m, 1 m apart, the first pushed, "
     "mu 0.6", double_domino, None),
    ("tilted-stack", "Box2D: 10 stacks of 10 unit boxes, each 0.2 m right of the one below, "
     "mu 0.3", tilted_stack, None),
)
"""``(pattern, description, builder, default number)`` of each field scene, for
:data:`ENTRIES`."""

EXAMPLE_NAMES = ("vertical-stack", "field-pyramid-10", "field-pyramid-20", "friction-ramps",
                 "high-mass-ratio-1", "high-mass-ratio-2", "overlap-recovery-friction",
                 "card-house", "double-domino", "tilted-stack")
"""The field scenes written to ``examples/`` (not ``large-pyramid``: 5050 bodies)."""


def example_text(name: str) -> str:
    """The ``examples/<name>.toml`` file of a library scene: a comment, then its TOML.

    The TOML is :meth:`Scene.to_toml`, every key in full, so the file loads to a scene
    equal to ``Scene.named(name)``.
    """
    header = (f"# The library's `{name}` (wuerfel_cvx.scenes.library: source and differences),\n"
              "# written by wuerfel_cvx.scenes.library.write_examples; do not edit by hand.\n")
    return header + Scene.named(name).to_toml()


def write_examples(directory: str | Path) -> list[Path]:
    """Write :data:`EXAMPLE_NAMES` as ``<name>.toml`` into ``directory``; the paths written."""
    target = Path(directory)
    paths = []
    for name in EXAMPLE_NAMES:
        path = target / f"{name}.toml"
        path.write_text(example_text(name), encoding="utf-8")
        paths.append(path)
    return paths


# ---------------------------------------------------------------------- closed-form friction scenes
GRAVITY = 9.81
"""Gravitational acceleration (m/s^2) of these scenes (the scenes' default)."""
LADDER_SIZE = (2.0, 0.1)
"""Length and thickness (m) of the ladder."""


SLOPE_BELOW = 8.0
"""Length (m) of slope below the square of :func:`slope_scene`."""


def slope_origin(angle: float) -> tuple[float, float]:
    """The point (m) of the slope's top face under the middle of the square's lower face.

    High enough that the whole slope is above the floor's top face (``y = 0``).
    """
    return 0.0, 1.1 * (math.cos(angle) + SLOPE_BELOW * math.sin(angle)) + 0.1


def slope_scene(angle: float = 0.4, friction: float = 0.3) -> Scene:
    """A unit square at rest on a table tilted by ``angle`` (rad), both of ``friction``.

    The floor comes first, as in every library scene, frictionless; the slope second.
    """
    if not 0.0 <= angle <= 1.0:
        raise ValueError(f"slope angle must be within 0 and 1 rad, got {angle}")
    origin = np.asarray(slope_origin(angle))
    normal = np.array([-math.sin(angle), math.cos(angle)])
    along = np.array([math.cos(angle), math.sin(angle)])
    length = 12.0
    table_centre = origin - 0.5 * normal + (0.5 * length - SLOPE_BELOW) * along
    table = Table(center=(float(table_centre[0]), float(table_centre[1])), size=(length, 1.0),
                  angle=angle, friction=friction)
    centre = origin + 0.5 * normal
    square = Square(center=(float(centre[0]), float(centre[1])), angle=angle,
                    friction=friction)
    floor = Table(center=(0.0, -0.5), size=(40.0, 1.0))
    return Scene(name="friction-slope", squares=(square,), tables=(floor, table))


def slope_acceleration(angle: float, friction: float) -> float:
    """The slide's acceleration (m/s^2) down the slope: ``g (sin - mu cos)``, or 0."""
    if friction >= math.tan(angle):
        return 0.0
    return GRAVITY * (math.sin(angle) - friction * math.cos(angle))


def launched_box_scene(speed: float = 3.0, friction: float = 0.5) -> Scene:
    """A unit square on a flat table launched at ``speed`` (m/s) along +x."""
    square = Square(center=(0.0, 0.5), velocity=(speed, 0.0), friction=friction)
    table = Table(center=(0.0, -0.5), size=(40.0, 1.0), friction=friction)
    return Scene(name="friction-slide", squares=(square,), tables=(table,))


def ramp_slide_scene(friction: float = 0.2, angle: float = 0.3, speed: float = 0.0,
                     clearance: float = 1e-3, ramp_friction: float | None = None) -> Scene:
    """A unit square on a ramp tilted by ``angle`` (rad, down towards +x), sliding down it.

    The square sits ``clearance`` (m) above the ramp's face, turned with it, moving at
    ``speed`` (m/s) down the slope; its friction is ``friction``, the ramp's
    ``ramp_friction`` (``friction`` when ``None``), the contacts' ``sqrt`` of the two.  With
    ``mu < tan(angle)`` it accelerates at ``g (sin(angle) - mu cos(angle))`` along the slope.
    """
    normal = (math.sin(angle), math.cos(angle))
    down = (math.cos(angle), -math.sin(angle))
    reach = 1.0 + clearance  # the ramp's half thickness and the square's half side
    square = Square(center=(reach * normal[0], reach * normal[1]), angle=-angle,
                    velocity=(speed * down[0], speed * down[1]), friction=friction)
    ramp = Table(center=(0.0, 0.0), size=(40.0, 1.0), angle=-angle,
                 friction=friction if ramp_friction is None else ramp_friction)
    return Scene(name="ramp-slide", squares=(square,), tables=(ramp,))


def _ladder_pose(angle: float) -> tuple[tuple[float, float], FloatArray]:
    """The ladder's centre (m) with its foot at the origin, and its corners ``(4, 2)``."""
    length, thickness = LADDER_SIZE
    corners = rectangle_corners((0.0, 0.0), length, thickness, angle)
    foot = corners[np.argmin(corners[:, 1])]
    return (float(-foot[0]), float(-foot[1])), corners - foot


def ladder_static_friction(angle: float) -> float:
    """The least floor coefficient (1) for which the ladder of :func:`ladder_scene` stands."""
    centre, corners = _ladder_pose(angle)
    wall_contact = corners[np.argmax(corners[:, 0])]
    return centre[0] / float(wall_contact[1])


def ladder_scene(friction: float = 0.3, angle: float = math.radians(60.0)) -> Scene:
    """The ladder (``angle`` from the floor) on a floor of ``friction``, a frictionless wall."""
    centre, corners = _ladder_pose(angle)
    wall_x = float(corners[:, 0].max())
    plank = Box(center=centre, size=LADDER_SIZE, angle=angle, friction=friction)
    floor = Table(center=(0.0, -0.5), size=(40.0, 1.0), friction=friction)
    wall = Table(center=(wall_x + 0.5, 2.0), size=(1.0, 4.0))
    return Scene(name="ladder", boxes=(plank,), tables=(floor, wall))


# ---------------------------------------------------------------------- the registry
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
    # the field's scenes, from Solver2D and Box2D v3
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
