"""The MuJoCo peer: the scene as planar rigid bodies in MuJoCo's x-z plane.

The scene's ``(x, y)`` plane is MuJoCo's ``(x, z)`` plane (``y`` is up in both), and
the model is written as MJCF text by :func:`scene_mjcf`.

Matched physics (SI units throughout)
-------------------------------------
* ``<option timestep=dt integrator="Euler">`` (s): MuJoCo's semi-implicit Euler (new
  velocities, then positions with them), so free flight is off the parabola by exactly
  ``|g| dt t / 2`` (m), as in the package's own stepping.  Gravity ``(gx, gy)`` (m/s^2)
  becomes ``(gx, 0, gy)``.
* Each square or box (in the order of ``Scene.bodies``: squares, then boxes) is a child
  body of the world at the origin with three joints, in this
  order: a slide along x (qpos = centre x, m), a slide along z (qpos = centre y, m) and
  a hinge about ``-y`` through the centre, so that a positive joint angle (rad) is the
  scene's counter-clockwise angle.  qvel is ``(vx, vy, omega)`` (m/s, m/s, rad/s).
* Its ``<inertial>`` has its mass ``m`` (kg) and ``diaginertia (I/2, I, I/2)``
  (kg m^2) with ``I = m (w^2 + h^2)/4``, the moment of the 4 corner masses of the
  package's model about the hinge (not the solid ``m (w^2 + h^2)/12``).  Only the hinge
  turns, so the other two components never act; halves of ``I`` add up to it exactly
  in floating point, which MuJoCo's triangle-inequality check needs (the lamina's own
  ``m h^2/4`` and ``m w^2/4`` can miss it by an ulp).
* Its geom is a box of half sizes ``(w/2, SQUARE_HALF_DEPTH, h/2)`` (m); tables are
  static box geoms of the world body, half sizes ``(w/2, TABLE_HALF_DEPTH, h/2)``,
  rotated by the table's angle about ``-y``.  The depths only place contact points along
  y, which exert no torque about the hinge.
* A scene without friction keys has frictionless contacts: ``condim="1"`` on every geom
  (normal force only; no restitution parameter exists, impacts are damped by the
  contact's ``solref``), and the MJCF text is exactly that of the frictionless model.
* Matched friction (a scene with a nonzero ``friction``): a geom of coefficient ``mu > 0``
  gets ``condim="3"`` and sliding friction ``mu`` (torsional and rolling coefficients only
  act at ``condim >= 4``).  MuJoCo combines two geoms of equal priority by the
  element-wise *maximum* of their coefficients and the larger condim, not by the
  package's ``sqrt(mu_a mu_b)``; the two agree when ``mu_a == mu_b``.  Every other pair
  that can touch (two moving bodies, or a moving body and a table) is written as an
  explicit ``<contact><pair>`` with ``condim`` 3 and friction ``sqrt(mu_a mu_b)`` (condim
  1 when that is 0).  MuJoCo's docs: a pair's parameters are its own, the geoms' are
  ignored, and its collision driver drops the dynamically found contact of a geom pair
  that an explicit pair covers, so each contact is generated once, with the matched
  coefficient.  A scene of ``k`` coefficients needs at most the pairs between bodies of
  different coefficients (none for one common coefficient).
* The cone is MuJoCo's default pyramidal one.  Bodies move only in the x-z plane, so the
  second tangent (along y) has a zero Jacobian and its two pyramid edges push along the
  normal only: the contact's set of forces is exactly ``|f_t| <= mu f_n``.  MuJoCo's
  computation chapter says so for 2-D contacts ("the pyramid is not even an
  approximation, but represents the same constraint set as the elliptic cone"); its soft
  regularisation still differs from the elliptic cone's.
* Contacts are otherwise MuJoCo's defaults, which are *soft*: ``solref = (0.02, 1)``
  (time constant 0.02 s, raised to ``2 dt`` when ``dt > 0.01`` s, critical damping) and
  ``solimp = (0.9, 0.95, 0.001, 0.5, 2)``; a resting body sits a fraction of a
  millimetre deep and landings penetrate further.  Default Newton solver (100
  iterations, tolerance 1e-8), pyramidal cone, no joint damping or armature.
* Every moving body is a child of the world, so they collide with each other and
  with the tables (parent filtering does not apply to the world); tables do not
  collide with each other.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...friction.forces import is_frictionless
from ...scenes.geometry import FloatArray
from ...scenes.scene import Scene
from ._common import initial_poses, matched_moment

ENGINE = "MUJOCO"
"""The engine's name in trajectories and metrics."""
PACKAGE = "mujoco"
"""The distribution that provides the engine."""
SQUARE_HALF_DEPTH = 0.5
"""Half extent (m) of a square's or box's geom along MuJoCo's y (out of the plane)."""
TABLE_HALF_DEPTH = 1.0
"""Half extent (m) of a table's box geom along y: deeper than any square."""


def _num(value: float) -> str:
    """A float as MJCF text without loss (``repr`` round-trips)."""
    return repr(float(value))


def _nums(*values: float) -> str:
    return " ".join(_num(v) for v in values)


def _contact_attributes(friction: float, frictional: bool) -> str:
    """A geom's condim and friction attributes: none in a frictionless scene."""
    if not frictional or friction == 0.0:
        return ""
    return f' condim="3" friction="{_num(friction)}"'


def _contact_pairs(scene: Scene) -> list[str]:
    """``<pair>`` lines for the geom pairs whose coefficients differ (``sqrt(mu_a mu_b)``)."""
    moving = [(f"square{i}", body.friction) for i, body in enumerate(scene.bodies)]
    tables = [(f"table{j}", table.friction) for j, table in enumerate(scene.tables)]
    candidates = [(a, b) for i, a in enumerate(moving) for b in moving[i + 1:]]
    candidates += [(a, b) for a in moving for b in tables]
    lines = []
    for (name_a, mu_a), (name_b, mu_b) in candidates:
        if mu_a == mu_b:
            continue  # MuJoCo's maximum is the matched coefficient
        mixed = math.sqrt(mu_a * mu_b)
        contact = (f'condim="3" friction="{_nums(mixed, mixed)}"' if mixed > 0.0
                   else 'condim="1"')
        lines.append(f'    <pair geom1="{name_a}" geom2="{name_b}" {contact}/>')
    return ["  <contact>", *lines, "  </contact>"] if lines else []


def scene_mjcf(scene: Scene, dt: float) -> str:
    """The MJCF XML text of a scene with time step ``dt`` (s); body ``square{i}`` per box."""
    gx, gy = scene.gravity
    frictional = not is_frictionless(scene)
    lines = [
        f'<mujoco model="wuerfel-{scene.name}">',
        '  <compiler angle="radian"/>',
        f'  <option timestep="{_num(dt)}" gravity="{_nums(gx, 0.0, gy)}" integrator="Euler"/>',
        '  <default><geom condim="1"/></default>',
        "  <worldbody>",
    ]
    for j, table in enumerate(scene.tables):
        (x, y), (w, h) = table.center, table.size
        lines.append(
            f'    <geom name="table{j}" type="box" pos="{_nums(x, 0.0, y)}"'
            f' axisangle="{_nums(0.0, -1.0, 0.0, table.angle)}"'
            f' size="{_nums(w / 2, TABLE_HALF_DEPTH, h / 2)}"'
            f'{_contact_attributes(table.friction, frictional)}/>'
        )
    for i, body in enumerate(scene.bodies):
        m, w, h = body.mass, body.width, body.height
        moment = matched_moment(m, w, h)
        lines += [
            f'    <body name="square{i}" pos="0 0 0">',
            f'      <joint name="square{i}_x" type="slide" axis="1 0 0"/>',
            f'      <joint name="square{i}_y" type="slide" axis="0 0 1"/>',
            f'      <joint name="square{i}_angle" type="hinge" axis="0 -1 0"/>',
            f'      <inertial pos="0 0 0" mass="{_num(m)}"'
            f' diaginertia="{_nums(moment / 2, moment, moment / 2)}"/>',
            f'      <geom name="square{i}" type="box"'
            f' size="{_nums(w / 2, SQUARE_HALF_DEPTH, h / 2)}"'
            f'{_contact_attributes(body.friction, frictional)}/>',
            "    </body>",
        ]
    lines.append("  </worldbody>")
    if frictional:
        lines += _contact_pairs(scene)
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"


class MujocoWorld:
    """A compiled MuJoCo model and its data holding a scene.

    ``model`` and ``data`` are the :class:`mujoco.MjModel` and :class:`mujoco.MjData`;
    body ``i`` of ``scene.bodies`` owns ``qpos[3i:3i+3] = (x, y, theta)`` and
    ``qvel[3i:3i+3]``.

    Parameters
    ----------
    scene:
        The scene.
    dt:
        Time step (s) of :meth:`step`.

    """

    def __init__(self, scene: Scene, dt: float) -> None:
        import mujoco

        self.xml = scene_mjcf(scene, dt)
        self.model: Any = mujoco.MjModel.from_xml_string(self.xml)
        self.data: Any = mujoco.MjData(self.model)
        self.n_boxes = scene.n_boxes
        if self.model.nq != 3 * self.n_boxes or self.model.nv != 3 * self.n_boxes:
            raise RuntimeError(f"expected 3 degrees of freedom per body, got nq = "
                               f"{self.model.nq}, nv = {self.model.nv}")
        poses = initial_poses(scene)
        self.data.qpos[:] = poses[:, 0:3].ravel()
        self.data.qvel[:] = poses[:, 3:6].ravel()
        mujoco.mj_forward(self.model, self.data)
        self._step = mujoco.mj_step

    def step(self) -> None:
        """Advance the model by one ``timestep`` (s) with ``mj_step``."""
        self._step(self.model, self.data)

    def poses(self) -> FloatArray:
        """Poses ``(n, 6)``: centre (m), angle (rad), velocity (m/s), spin (rad/s)."""
        q = np.asarray(self.data.qpos, dtype=np.float64).reshape(self.n_boxes, 3)
        v = np.asarray(self.data.qvel, dtype=np.float64).reshape(self.n_boxes, 3)
        return np.concatenate([q, v], axis=1)

    def n_contacts(self) -> int:
        """Contacts MuJoCo found at the start of the last step (``data.ncon``)."""
        return int(self.data.ncon)


def build_world(scene: Scene, dt: float) -> MujocoWorld:
    """The scene as a MuJoCo model with the matched settings of this module."""
    return MujocoWorld(scene, dt)


def engine_version() -> str:
    """MuJoCo's version string (raises ImportError without mujoco)."""
    import mujoco

    return str(mujoco.__version__)
