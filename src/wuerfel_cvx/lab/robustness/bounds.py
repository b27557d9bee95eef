"""Per-step bounds of a run's penetration and energy rise, derived from its own states.

The bounds are derived here, not fitted; :func:`~wuerfel_cvx.lab.robustness.properties.check_run`
asserts them.  They depend on how the ``velocity`` formulation linearises its contacts
(:mod:`~wuerfel_cvx.formulations.velocity`).

Penetration, ``linearisation="start"`` (``velocity-baumgarte``)
    Let ``d(t)`` be the signed distance of corner ``k`` of body B from the edge line of
    body A it is matched to, while both move rigidly over a step with the constant
    centre velocities and spins ``omega_A``, ``omega_B`` that the step's solution
    describes (exactly the motion of :func:`~wuerfel_cvx.formulations.motion.rigid_step`).
    With ``n`` the edge's unit normal (turning at ``omega_A``), ``Delta = p_k - p_i``::

        d = n . Delta,   d'' = -omega_A^2 d + 2 omega_A rot90(n) . Delta' + n . Delta''

    and ``|Delta''| <= omega_A^2 r_A + omega_B^2 r_B`` (centripetal accelerations of
    the two corners, ``r`` the half diagonal), ``|Delta'| <= 2 V`` (``V`` the largest
    corner speed), ``|d| <= r_A + r_B`` for a matched pair.  So with ``Omega`` the largest
    spin and ``R`` the largest half diagonal, ``|d''| <= 4 Omega^2 R + 4 Omega V``.  The QP
    constrains the first-order prediction ``d + dt d'(0)`` (``d'(0) = grad d . v+``):
    ``>= 0`` for a point outside (speculative contact) and ``>= (1 - beta) d`` for a
    point inside (Baumgarte).  Taylor's theorem with the remainder gives the depth after
    the step::

        depth_k <= (1 - beta) depth_{k-1} + eps_k,
        eps_k = dt^2 / 2 (4 Omega^2 R + 4 Omega V) + dt * s_k

    where ``s_k`` is the contact-rate error the residual check admits (``s_k = r_k
    (1 + 6 V + margin / dt + 2 dt |g|)`` with ``r_k`` the step's relative primal
    residual and the bracket a bound on the primal scale of
    :func:`~wuerfel_cvx.solve.paths.kkt_residuals`: right-hand sides ``|d| / dt`` with ``|d|``
    within the two bodies' reach ``margin + dt (2 V + 2 dt |g|)``, and rows ``|G v+| <=
    3 V``, the gradient of a distance being a unit normal split over three points).
    The depth measured after the step is at most that of the matched edge, so the
    recursion bounds the metric.  This is the
    ``(omega dt)^2 r / 2`` of the README's "Known limitations", with the edge's own
    spin and the Coriolis term included; for a body at rest or sliding without spin
    the bound is the solver's tolerance alone.

Penetration, ``linearisation="closest-approach"`` (``velocity``, the default)
    A step is accepted only once, along the accepted solution's own rigid motion (the one
    :func:`~wuerfel_cvx.formulations.motion.rigid_step` performs), no contact's gap falls
    below its ramp by more than ``gap_tolerance`` (:mod:`~wuerfel_cvx.formulations.velocity`;
    the end of the step is one of the sampled times).  The ramp ends at
    ``c = min(0, phi_0 + dt u_push)`` with ``phi_0 >= -depth_{k-1}``, so every contact's depth
    after step ``k`` is at most::

        max(0, depth_{k-1} - dt u_push) + gap_tolerance

    with ``u_push`` the push-out speed and ``depth_{k-1}`` the measured depth before the step.
    The solver's inexactness does not enter: the check is on the motion itself, not on
    the linearised rows.  A step that reaches ``max_passes`` before it is accepted can
    exceed the bound, and is reported.

Friction (``friction_model="ccp"``)
    The cone rows of :mod:`~wuerfel_cvx.formulations.cone` keep their normal rows'
    right-hand sides ``h``, so the identity below holds with every cone row among the
    rows and the bounds are the frictionless ones: the friction impulses' work is part of
    ``nu . h``, and with complementarity it is ``-mu lambda_n |s| <= 0`` for each sliding
    contact (checked in ``tests/test_friction_analytic.py``).  Friction never adds energy.

Energy, ``linearisation="start"``
    With ``w = v + dt g`` and the step's multipliers ``nu`` (impulses: the objective has
    no 1/2, so they are half the QP's duals), stationarity gives
    ``M (v+ - w) = J^T nu``, and with complementarity ``nu . J v+ = nu . h`` the energy
    change of a step (kinetic ``|v|_M^2 / 2`` plus potential ``-M g . p``; the centres
    move by ``dt`` times the mean corner velocity) is, in the mass norm::

        E+ - E = nu . h - |v+ - v|_M^2 / 2

    (checked against the QP's own duals in ``tests/test_properties.py``).  Speculative
    rows have ``h <= 0`` and ``nu >= 0``, rods have ``h = 0`` to round-off: frictionless
    contacts with restitution 0 do no positive work, and energy only falls, except
    (a) through Baumgarte rows (``h = beta depth / dt > 0``) and (b) the solver's
    inexactness.  (a) A depth ``P`` pushed out at rate ``beta / dt`` through at most
    ``n`` stacked squares gives a velocity change ``u <= n beta P / dt`` to a total
    mass ``M`` whose corners move at most at ``V``: kinetic energy grows by at most
    ``M (V u + u^2 / 2)`` and potential energy by ``M |g| dt u``.  This assumes the
    impulses are of the size of the momentum they change; a penetrated corner that can
    hardly be pushed out without breaking the contacts around it (nearly redundant
    rows) takes far larger impulses and injects more: such runs are reported.
    (b) With relative residuals ``p`` (primal), ``d`` (dual), ``c`` (complementarity)
    as :func:`~wuerfel_cvx.solve.paths.kkt_residuals` defines them, the identity above is off
    by ``sum nu_i s_i`` (``s`` the rows' slack, bounded through ``c`` and ``p`` times
    the primal scale) and by the stationarity error times ``V``; bounding every dual by
    twice the momentum ``M (2 V + dt |g|)`` gives
    ``N_rows (c (1 + Z S) + p Z S) / 2 + N_var d (1 + Z_1) V / 2`` with ``Z`` that bound,
    ``Z_1`` the same for the heaviest square, ``S`` the primal scale.  A rise above
    (a) + (b) + round-off is a violation.  Free flight itself loses
    ``M |g|^2 dt^2 / 2`` per step (semi-implicit Euler), which is not credited.

Energy, ``linearisation="closest-approach"``
    The same identity holds with the rows of the last pass (two per contact).  A rate row
    ``G_0 v >= r'`` with ``r' = (c - phi_0) / dt`` is, when active, ``G_0 v+ = r'``.  An
    approach row at ``tau*`` has right-hand side ``min(G_1 v0 - psi(tau*; v0) / tau*, r')
    <= r'`` (:mod:`~wuerfel_cvx.formulations.velocity`), so when active ``G_1 v+ <= r'``
    too.  ``r' <= 0`` for a point outside; for one inside it is the push-out rate
    ``min(depth, dt u_push) / dt``.  So ``nu . h`` is at most the push-out's work, which is
    bounded as (a) above with ``u = n min(depth / dt, u_push)`` in place of ``n beta P / dt``
    (depths are at ``gap_tolerance`` after every accepted step), and (b) is unchanged.
    No curvature term enters: a spinning corner's closest approach is where its gap's
    rate equals the ramp's.

"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...formulations import (
    DEFAULT_FORMULATION,
    Formulation,
    RigidFormulation,
    VelocityFormulation,
    get_formulation,
)
from ...formulations.rigid import body_velocities
from ...scenes.scene import Scene, half_diagonal
from ...step.metrics import deepest_penetration
from ...step.model import Model
from ...trajectory import Trajectory

ROUND_OFF_LENGTH = 1e-9
"""Round-off floor (m) for the penetration bound: positions are O(10) m, eps 2e-16."""
ROUND_OFF_ENERGY_RELATIVE = 1e-11
"""Round-off floor for energy, relative to the largest energy magnitude of the run."""


@dataclass(frozen=True)
class RunBounds:
    """Per-step bounds of a run, derived from its own states (see the module docstring)."""

    penetration: np.ndarray
    """Largest depth (m) the formulation allows after each step, ``(steps,)``."""
    energy_rise: np.ndarray
    """Largest total-energy rise (J) each step may show, ``(steps,)``."""


@dataclass(frozen=True)
class _RunData:
    """What the bounds read from a run: per step ``k`` (the step to state ``k + 1``)."""

    dt: float
    gravity: float
    masses: np.ndarray
    radius: float
    omega: np.ndarray
    velocity: np.ndarray
    depth_before: np.ndarray
    depth_start: float
    primal: np.ndarray
    dual: np.ndarray
    complementarity: np.ndarray
    n_rows: np.ndarray
    n_variables: np.ndarray
    energy_scale: float


def formulation_of(trajectory: Trajectory,
                   formulation: Formulation | None) -> VelocityFormulation:
    """``formulation``, or the velocity formulation the trajectory names.

    A ``rigid`` formulation poses its velocity formulation's QP in three unknowns per body
    (the same rows, the rods exact), so its bounds are that formulation's.
    """
    scheme = formulation if formulation is not None else get_formulation(
        str(trajectory.info.get("formulation", DEFAULT_FORMULATION)))
    if isinstance(scheme, RigidFormulation):
        scheme = scheme.velocity_equivalent
    if not isinstance(scheme, VelocityFormulation):
        raise ValueError(f"the bounds are derived for the velocity formulations, not "
                         f"'{scheme.name}'")
    return scheme


def run_bounds(trajectory: Trajectory, scene: Scene,
               formulation: Formulation | None = None) -> RunBounds:
    """The penetration and energy-rise bounds of each step of ``trajectory`` (of ``scene``).

    ``formulation``: the one the run used, by default the one its ``info`` names.
    """
    scheme = formulation_of(trajectory, formulation)
    data = _run_data(trajectory, scene)
    if scheme.linearisation == "start":
        penetration = _start_penetration(data, scheme)
        push = scene.n_boxes * scheme.beta * data.depth_before / data.dt
    else:
        penetration = (np.maximum(0.0, data.depth_before - data.dt * scheme.push_speed)
                       + scheme.gap_tolerance + ROUND_OFF_LENGTH)
        push = scene.n_boxes * np.minimum(data.depth_before / data.dt, scheme.push_speed)
    return RunBounds(penetration=penetration,
                     energy_rise=_energy_rise(data, push, scheme.contact_margin))


def _run_data(trajectory: Trajectory, scene: Scene) -> _RunData:
    steps = trajectory.n_steps
    spin, speed = _spins_and_speeds(trajectory, scene.n_boxes)
    depth_start = deepest_penetration(Model.from_scene(scene), trajectory.points[0])
    metrics = trajectory.metrics
    primal, dual, complementarity = (
        np.nan_to_num(metrics[column].to_numpy()[:steps], nan=1.0)
        for column in ("primal_residual", "dual_residual", "complementarity"))
    energy = metrics["total_energy_J"].to_numpy()
    return _RunData(
        dt=float(trajectory.info["dt"]), gravity=float(np.hypot(*scene.gravity)),
        masses=np.array([b.mass for b in scene.bodies]),
        radius=max(half_diagonal(b) for b in scene.bodies),
        # the spin and speed of step k are those of the state after it (rigid_step keeps them)
        omega=spin[1:], velocity=np.maximum(speed[1:], speed[:-1]),
        depth_before=np.concatenate([[depth_start],
                                     metrics["penetration_m"].to_numpy()[:steps - 1]]),
        depth_start=depth_start, primal=primal, dual=dual, complementarity=complementarity,
        n_rows=metrics[["n_equalities", "n_inequalities"]].to_numpy().sum(axis=1)[:steps],
        n_variables=metrics["n_variables"].to_numpy()[:steps],
        energy_scale=max(1.0, float(np.nanmax(np.abs(energy))) if energy.size else 1.0))


def _spins_and_speeds(trajectory: Trajectory, n_squares: int) -> tuple[np.ndarray, np.ndarray]:
    """Largest spin (rad/s) and corner speed (m/s) per state, ``(steps + 1,)`` each."""
    states = trajectory.points.shape[0]
    # every state's squares at once: the fit is per square (equal corner masses)
    _, spin = body_velocities(trajectory.points.reshape(-1, 2),
                              trajectory.velocities.reshape(-1, 2),
                              np.ones((states * n_squares, 4)))
    speed = np.linalg.norm(trajectory.velocities, axis=2)
    return np.abs(spin).reshape(states, n_squares).max(axis=1), speed.max(axis=1)


def _primal_scale(data: _RunData, margin: float) -> np.ndarray:
    """The primal scale of the residual check per step (see the module docstring)."""
    scale: np.ndarray = np.asarray(1.0 + 6.0 * data.velocity + margin / data.dt
                                   + 2.0 * data.dt * data.gravity)
    return scale


def _start_penetration(data: _RunData, scheme: VelocityFormulation) -> np.ndarray:
    """The recursion ``depth_k <= (1 - beta) depth_{k-1} + eps_k`` of the start rows."""
    dt, omega, velocity = data.dt, data.omega, data.velocity
    overshoot = (0.5 * dt**2 * (4.0 * omega**2 * data.radius + 4.0 * omega * velocity)
                 + dt * data.primal * _primal_scale(data, scheme.contact_margin))
    penetration = np.empty(omega.size)
    depth = data.depth_start  # 0 for scenes that start apart
    for k in range(omega.size):
        depth = (1.0 - scheme.beta) * depth + overshoot[k] + ROUND_OFF_LENGTH
        penetration[k] = depth
    return penetration


def _energy_rise(data: _RunData, push: np.ndarray, margin: float) -> np.ndarray:
    """Push-out work (a) plus the solver's inexactness (b) plus round-off, per step (J)."""
    velocity, gravity, dt = data.velocity, data.gravity, data.dt
    total_mass = float(data.masses.sum())
    pushed = total_mass * (velocity * push + 0.5 * push**2 + gravity * dt * push)
    # multipliers are twice the impulses (objective without 1/2); an impulse is at most
    # the momentum that stops or reverses the whole scene, or one square for the
    # stationarity terms
    impulse_total = 2.0 * total_mass * (2.0 * velocity + dt * gravity)
    impulse_square = 2.0 * data.masses.max() * (2.0 * velocity + dt * gravity)
    scale = _primal_scale(data, margin)
    inexact = (0.5 * data.n_rows * (data.complementarity * (1.0 + impulse_total * scale)
                                    + data.primal * impulse_total * scale)
               + 0.5 * data.n_variables * data.dual * (1.0 + impulse_square) * velocity)
    rise: np.ndarray = pushed + inexact + ROUND_OFF_ENERGY_RELATIVE * data.energy_scale
    return rise
