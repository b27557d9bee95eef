"""The field's benchmark scenes: Solver2D's and Box2D v3's samples in this package's bodies.

Each scene is translated from its definition in Erin Catto's public repositories
(``erincatto/solver2d`` at commit d178a56, ``erincatto/box2d`` at commit 617d32a):

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
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from ..errors import InputError
from .bodies import Box, Square, Table, Vec2
from .scene import Scene

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
:data:`wuerfel_cvx.scenes.library.ENTRIES`."""

EXAMPLE_NAMES = ("vertical-stack", "field-pyramid-10", "field-pyramid-20", "friction-ramps",
                 "high-mass-ratio-1", "high-mass-ratio-2", "overlap-recovery-friction",
                 "card-house", "double-domino", "tilted-stack")
"""The field scenes written to ``examples/`` (not ``large-pyramid``: 5050 bodies)."""


def example_text(name: str) -> str:
    """The ``examples/<name>.toml`` file of a library scene: a comment, then its TOML.

    The TOML is :meth:`Scene.to_toml`, every key in full, so the file loads to a scene
    equal to ``Scene.named(name)``.
    """
    header = (f"# The library's `{name}` (wuerfel_cvx.scenes.field: source and differences),\n"
              "# written by wuerfel_cvx.scenes.field.write_examples; do not edit by hand.\n")
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
