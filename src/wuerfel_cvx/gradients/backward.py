"""Backpropagation through a recorded run: a loss's gradient with respect to its inputs.

For a loss ``L`` of the recorded corner positions (its gradient ``dL/dpoints`` shaped like
:attr:`Trajectory.points <wuerfel_cvx.trajectory.Trajectory.points>`), the backward pass
carries the adjoint of each state, per body ``(a_c, a_theta, a_u, a_omega)`` (the rigid
coordinates of :mod:`wuerfel_cvx.gradients.rigid`), from the last state to the first:

1. the loss's own part at state ``k``: ``a_c += sum_corners dL/dp``, ``a_theta += sum dL/dp .
   rot90(r)``;
2. through the advance of step ``k`` (``c' = c + dt u*``, ``theta' = theta + dt omega*``, ``u' =
   u*``, ``omega' = omega*``): ``a_c`` and ``a_theta`` pass on, and ``dL/dx* = (dt a_c + a_u,
   dt a_theta + a_omega)``;
3. through the QP's solution (:func:`~wuerfel_cvx.gradients.adjoint.qp_adjoint`, one solve
   with the reduced KKT matrix of the polished active set) to its numbers, and from them to
   the state at ``k`` and the parameters: the target ``(u + dt g, omega)`` to ``a_u``,
   ``a_omega`` and gravity, the weights to the masses, the tight rows
   (:func:`~wuerfel_cvx.gradients.rigid.contact_rows`) to ``a_c``, ``a_theta`` and the
   friction coefficients.

At the first state ``a_c``, ``a_theta``, ``a_u``, ``a_omega`` are the gradients with respect to
the scene's ``center``, ``angle``, ``velocity`` and ``angular_velocity``.  Through
``velocity`` (corner-velocity unknowns held by rods) the state adjoint is the same; steps 2
and 3 go through the fit of the corner velocities to the bodies' motion, and the rods'
equalities join the rows (:mod:`~wuerfel_cvx.gradients.velocity`).  The cost is one
sparse LDL-like factorisation of each step's reduced KKT matrix, about what the polish of
the forward run paid.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from ..formulations.qp import StepQP
from ..formulations.velocity import FIRST_DAMPED_PASS
from ..scenes.geometry import FloatArray, rot90
from ..solve.kkt import EXACT_OUTCOMES, ActiveSet, guess_active_set
from ..solve.paths import StepSolution
from ..step.model import IntArray, Model
from .adjoint import (
    GAP_SWITCH,
    FrictionAdjoint,
    QPAdjoint,
    coulomb_adjoint,
    gap_switch_rows,
    qp_adjoint,
    unshifted_target,
    weak_rows,
)
from .rigid import (
    LOCAL,
    ApproachPass,
    ContactRows,
    approach_contacts,
    approach_rows_of,
    body_columns,
    cone_rows,
    contact_rows,
    corner_rows,
    corner_slips,
    row_contacts,
    slip_rows,
)
from .tape import WRT_NAMES, GradientError, GradientTape, StepTape
from .velocity import (
    CornerFit,
    approach_view,
    check_rows,
    corner_local,
    fit_turns,
    objective_back,
    rods_back,
)

if TYPE_CHECKING:
    from ..trajectory import Trajectory


def checked_names(wrt: str | tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """``wrt`` as a tuple of :data:`~wuerfel_cvx.gradients.tape.WRT_NAMES`, or an error."""
    names = (wrt,) if isinstance(wrt, str) else tuple(wrt)
    unknown = [name for name in names if name not in WRT_NAMES]
    if unknown or not names:
        raise GradientError(f"unknown gradient name(s) {unknown or '(none)'} (one or more of "
                            f"{', '.join(WRT_NAMES)})", field="wrt")
    return names


class _Adjoints:
    """The adjoint of the current state and of the parameters, per body."""

    def __init__(self, n: int):
        self.center = np.zeros((n, 2))
        self.angle = np.zeros(n)
        self.velocity = np.zeros((n, 2))
        self.angular_velocity = np.zeros(n)
        self.friction = np.zeros(n)
        self.mass = np.zeros(n)
        self.gravity = np.zeros(2)

    def add_points(self, points: FloatArray, dloss: FloatArray) -> None:
        """Step 1 of the module docstring: the loss's part at one state."""
        corners = points.reshape(-1, 4, 2)
        offsets = corners - corners.mean(axis=1)[:, None, :]
        per_corner = dloss.reshape(-1, 4, 2)
        self.center += per_corner.sum(axis=1)
        self.angle += np.sum(per_corner * rot90(offsets), axis=(1, 2))


def gradient(trajectory: Trajectory, tape: GradientTape | None, dloss_dpoints: FloatArray,
             wrt: str | tuple[str, ...] | list[str]) -> dict[str, FloatArray]:
    """``dL/d(wrt)`` for a loss whose gradient with respect to the recorded points is given.

    Returns each requested name's array (shapes in
    :data:`~wuerfel_cvx.gradients.tape.WRT_NAMES`) and three entries on where the derivative
    is one-sided: ``flagged_steps`` (the 1-based steps with a weakly active row or an answer
    whose polish was rejected, whose active set was then guessed), ``weak_rows`` (the number
    of weakly active rows per flagged step), ``crossings`` (how many steps were flagged, a
    0-d array) and ``gap_switch_steps`` (steps with a tight row at the switch between a
    speculative and a Baumgarte rate, :data:`~wuerfel_cvx.gradients.adjoint.GAP_SWITCH`).
    See :meth:`Trajectory.gradient <wuerfel_cvx.trajectory.Trajectory.gradient>`.
    """
    names = checked_names(wrt)
    if tape is None:
        raise GradientError("this trajectory was recorded without gradients: run "
                            "simulate(..., gradients=True)")
    dloss = np.asarray(dloss_dpoints, dtype=np.float64)
    if dloss.shape != trajectory.points.shape:
        raise GradientError(f"dloss_dpoints has shape {dloss.shape}, the points "
                            f"{trajectory.points.shape}", field="dloss_dpoints")
    if len(tape.steps) != trajectory.n_steps:
        raise GradientError(f"the tape holds {len(tape.steps)} steps, the trajectory "
                            f"{trajectory.n_steps}")
    unverified = [record.step for record in tape.steps if not record.solution.verified]
    if unverified:
        raise GradientError(f"steps {unverified[:10]} were not verified: no gradient is taken "
                            f"through an answer that failed its KKT check")
    adjoints = _Adjoints(tape.model.n_boxes)
    flagged, weak, switches = [], [], []
    actives = [[_active(record, qp, solution) for qp, solution in _chain(record)]
               for record in tape.steps]
    approach: dict[int, list[ContactRows | None]] = {}
    for index in range(len(tape.steps) - 1, -1, -1):
        if index not in approach:
            approach = _approach_rows(tape, trajectory.points, actives, index)
        record = tape.steps[index]
        k = record.step
        adjoints.add_points(trajectory.points[k], dloss[k])
        count, at_switch = _step_back(tape, record, trajectory.points[k - 1], adjoints,
                                      actives[index], approach.pop(index))
        if count:
            flagged.append(k)
            weak.append(count)
        if at_switch:
            switches.append(k)
    adjoints.add_points(trajectory.points[0], dloss[0])
    result = {name: np.array(getattr(adjoints, name)) for name in names}
    result["flagged_steps"] = np.array(flagged[::-1], dtype=np.int64)
    result["weak_rows"] = np.array(weak[::-1], dtype=np.int64)
    result["crossings"] = np.array(len(flagged))
    result["gap_switch_steps"] = np.array(switches[::-1], dtype=np.int64)
    return result


def _closest_approach(tape: GradientTape) -> bool:
    """Whether the run's rows are rigid's closest-approach rows (Gauss-Newton passes)."""
    return getattr(tape.formulation, "linearisation", "start") == "closest-approach"


def _chain(record: StepTape) -> tuple[tuple[StepQP, StepSolution], ...]:
    """A step's QPs with their answers, its first pass first, the step's own QP last."""
    return record.passes + ((record.qp, record.solution),)


def _active(record: StepTape, qp: StepQP, solution: StepSolution) -> tuple[ActiveSet, bool]:
    """An answer's active set, and whether it was guessed (its polish rejected)."""
    if not solution.verified:
        raise GradientError(f"step {record.step}: a pass was not verified")
    guessed = solution.polish not in EXACT_OUTCOMES or solution.active is None
    active = solution.active
    if active is None:
        active = guess_active_set(qp, solution.x, solution.ineq_dual)
    return active, guessed


BLOCK_CONTACTS = 4096
"""Contacts whose closest-approach rows :func:`_approach_rows` finds together: a few
stacked evaluations' worth (:data:`~wuerfel_cvx.gradients.rigid.STACKED_CONTACTS`), the
rows' derivatives of a block of steps held at a time (about 3 kB a contact)."""


def _approach_rows(tape: GradientTape, points: FloatArray,
                   actives: list[list[tuple[ActiveSet, bool]]], last: int,
                   ) -> dict[int, list[ContactRows | None]]:
    """Closest-approach rows with their tight rows' derivatives, by step index and pass.

    Step ``last``'s and its predecessors' up to :data:`BLOCK_CONTACTS` contacts.  ``None``
    for a pass without tight rows, and for every pass of a run with rows at the start.  The
    block's passes in one :func:`~wuerfel_cvx.gradients.rigid.approach_rows_of` (a few
    stacked evaluations rather than two per pass): the rows depend on the recorded
    run alone, not on the adjoint.
    """
    if not _closest_approach(tape):
        return {last: [None] * len(actives[last])}
    found: dict[int, list[ContactRows | None]] = {}
    where, passes, contacts = [], [], 0
    for index in range(last, -1, -1):
        if contacts >= BLOCK_CONTACTS:
            break
        record, step = tape.steps[index], actives[index]
        found[index] = [None] * len(step)
        _about_rule(record, _chain(record))
        for position, ((qp, _), (active, _)) in enumerate(zip(_chain(record), step,
                                                              strict=True)):
            tight = np.concatenate([active.lower, active.upper]).astype(np.int64)
            if tight.size:
                where.append((index, position))
                passes.append(_approach_pass(tape, points[record.step - 1], qp, tight))
                contacts += len(qp.contacts)
    rows = approach_rows_of(tape.model, passes,
                            float(getattr(tape.formulation, "push_speed", 1.0)), tape.dt)
    for (index, position), found_rows in zip(where, rows, strict=True):
        found[index][position] = found_rows
    return found


def _approach_pass(tape: GradientTape, points: FloatArray, qp: StepQP,
                   tight: np.ndarray) -> ApproachPass:
    """The pass to differentiate for ``qp``'s ``tight`` rows (``velocity``: its view)."""
    if not _corner_space(tape):
        return points, qp, tight
    normal, _ = cone_rows(qp, True)
    view = approach_view(tape.model, points, qp, float(getattr(tape.formulation, "push_speed",
                                                              1.0)), tape.dt)
    return points, view, np.unique(normal[tight])


def _step_back(tape: GradientTape, record: StepTape, points: FloatArray,
               adjoints: _Adjoints, actives: list[tuple[ActiveSet, bool]],
               approach: list[ContactRows | None]) -> tuple[int, int]:
    """Carry ``adjoints`` from the state after ``record``'s step to the state before it.

    Returns how many of its rows are weakly active (at least 1 for an answer whose polish
    was rejected, whose active set is then guessed from the answer), and how many of its
    tight rows sit at the gap switch (:func:`~wuerfel_cvx.gradients.adjoint.gap_switch_rows`).

    With closest-approach rows the step's passes are chained (:func:`_about_rule`): pass
    ``q``'s rows depend on its linearisation point, the target for the first pass, the first
    answer for the second, the mean of the last answer and the last point after that.
    ``velocity``'s unknowns are corner velocities: its advance, rods, rows and objective go
    through the fit of :mod:`~wuerfel_cvx.gradients.velocity`.
    """
    dt = tape.dt
    closest = _closest_approach(tape)
    chain = _chain(record)
    fit = CornerFit.of(tape.model, points) if _corner_space(tape) else None
    a_x = np.concatenate([dt * adjoints.center + adjoints.velocity,
                          (dt * adjoints.angle + adjoints.angular_velocity)[:, None]],
                         axis=1).ravel()
    if fit is not None:  # the advance by the motion the corner velocities describe
        adjoints.angle += fit.turns(a_x[2::3], record.solution.x)
        a_x = fit.to_corners(a_x)
    size = record.qp.n_variables
    a_target, a_weights, carried = np.zeros(size), np.zeros(size), np.zeros(size)
    weak, switches = 0, 0
    for index in range(len(chain) - 1, -1, -1):
        qp, solution = chain[index]
        adjoint, friction, flagged, active = _pass_adjoint(record, qp, solution, a_x,
                                                           index == len(chain) - 1,
                                                           actives[index])
        weak, switches = weak + flagged, switches + _switches(tape, qp, active)
        a_target += adjoint.target
        a_weights += adjoint.weights
        about = carried + _pass_rows_back(tape, fit, qp, solution.x, points, adjoint,
                                          adjoints, approach[index])
        if friction is not None:
            _slips_back(tape, record, points, friction, adjoint.unknowns_adjoint, adjoints,
                        fit is not None)
        if fit is not None:
            adjoints.angle += rods_back(tape.model, points, solution.x, adjoint)
        if not closest:
            continue
        if index == 0:  # the first pass is linearised about the target
            a_target += about
        elif index + 1 < FIRST_DAMPED_PASS:  # the next ones about the last answer
            a_x, carried = about, np.zeros(size)
        else:  # later ones about the mean of the last answer and the last point
            a_x, carried = 0.5 * about, 0.5 * about
    _objective_back(tape, record, fit, a_target, a_weights, adjoints)
    return weak, switches


def _corner_space(tape: GradientTape) -> bool:
    """Whether the run's unknowns are corner velocities held by rods (``velocity``)."""
    return bool(getattr(tape.formulation, "rods", False))


def _objective_back(tape: GradientTape, record: StepTape, fit: CornerFit | None,
                    a_target: FloatArray, a_weights: FloatArray, adjoints: _Adjoints) -> None:
    """The target's and weights' adjoints to the start velocities, gravity and masses."""
    dt, n = tape.dt, tape.model.n_boxes
    if fit is not None:
        part = objective_back(fit, tape.model, record.qp, a_target, a_weights, dt)
        adjoints.velocity, adjoints.angular_velocity = part.velocity, part.angular_velocity
        adjoints.angle += part.angle
        adjoints.gravity += part.gravity
        adjoints.mass += part.mass
        return
    target = a_target.reshape(n, 3)
    adjoints.velocity = target[:, :2].copy()
    adjoints.angular_velocity = target[:, 2].copy()
    adjoints.gravity += dt * target[:, :2].sum(axis=0)
    weights = a_weights.reshape(n, 3)
    inertia_per_mass = record.qp.weights[2::3] / record.qp.weights[0::3]
    adjoints.mass += weights[:, 0] + weights[:, 1] + weights[:, 2] * inertia_per_mass


def _pass_rows_back(tape: GradientTape, fit: CornerFit | None, qp: StepQP, x: FloatArray,
                    points: FloatArray, adjoint: QPAdjoint, adjoints: _Adjoints,
                    approach: ContactRows | None) -> FloatArray:
    """A pass's tight rows to ``adjoints``; the adjoint of its linearisation point.

    In the pass's unknowns (zeros for rows at the step's start or no tight row).
    """
    if not adjoint.rows.size:
        return np.zeros(qp.n_variables)
    if fit is None:
        return _rows_back(tape, qp, x, points, adjoint, adjoints, approach)
    return _corner_rows_back(tape, fit, qp, x, points, adjoint, adjoints, approach)


def _corner_rows_back(tape: GradientTape, fit: CornerFit, qp: StepQP, x: FloatArray,
                      points: FloatArray, adjoint: QPAdjoint, adjoints: _Adjoints,
                      approach: ContactRows | None) -> FloatArray:
    """``velocity``'s tight rows (:mod:`~wuerfel_cvx.gradients.velocity`).

    Start rows: three corner blocks each.  Closest-approach rows: rigid's rows ``N``
    (``approach``, of :func:`~wuerfel_cvx.gradients.velocity.approach_view`) through the
    fit, plus the cones' slip blocks; returns the linearisation point's adjoint in corner
    velocities.
    """
    model, contacts = tape.model, qp.contacts
    closest = _closest_approach(tape)
    if closest and approach is None:
        raise GradientError("a closest-approach pass's tight rows were not differentiated")
    normal, sign = cone_rows(qp, closest)
    contact = normal % max(len(contacts), 1)
    rate = None if closest else np.where(contacts.distance > 0.0, 1.0 / tape.dt,
                                         float(getattr(tape.formulation, "beta", 0.2))
                                         / tape.dt)
    rows = corner_rows(model, points, contacts, contact, sign, rate)
    check_rows(model, qp, fit, approach, normal, rows)
    tight = adjoint.rows
    bodies = (contacts.edge_body[contact[tight]], contacts.point_body[contact[tight]])
    _scatter(model, *bodies, corner_local(model, rows, tight, adjoint.row_multiplier,
                                          adjoint.row_adjoint, adjoint.unknowns_adjoint, x),
             adjoints)
    if approach is None:
        return np.zeros(qp.n_variables)
    seen = dataclasses.replace(adjoint, rows=normal[tight],
                               unknowns_adjoint=fit.to_bodies(adjoint.unknowns_adjoint))
    about = _rows_back(tape, qp, fit.to_bodies(x), points, seen, adjoints, approach)
    adjoints.angle += fit_turns(model, fit, approach, normal[tight], bodies, adjoint, x)
    assert qp.linearised_about is not None
    adjoints.angle += fit.turns(about[2::3], qp.linearised_about)
    return fit.to_corners(about)


ABOUT_CHECK = 1e-9
"""Largest difference (relative to the largest velocity, plus 1 m/s) between a pass's
recorded linearisation point and the one :func:`_about_rule` expects."""


def _about_rule(record: StepTape, chain: tuple[tuple[StepQP, StepSolution], ...]) -> None:
    """Refuse a step whose passes were not linearised as the backward pass chains them.

    Pass 1 about the step's target (without a Coulomb step's friction impulse), pass ``q``
    below :data:`~wuerfel_cvx.formulations.velocity.FIRST_DAMPED_PASS` about pass
    ``q - 1``'s answer, later ones about the mean of pass ``q - 1``'s answer and point
    (:meth:`RigidFormulation.refine <wuerfel_cvx.formulations.rigid.RigidFormulation.
    refine>`).  A Coulomb step whose fixed point re-linearised its rows is refused: its
    passes interleave with friction problems, and are not chained.
    """
    target = (record.qp.target if record.forces is None
              else unshifted_target(record.qp, record.forces))
    expected = [target]
    for index in range(1, len(chain)):
        answer, last = chain[index - 1][1].x, chain[index - 1][0].linearised_about
        expected.append(answer if index + 1 < FIRST_DAMPED_PASS or last is None
                        else 0.5 * (answer + last))
    for (qp, _), about in zip(chain, expected, strict=True):
        recorded = qp.linearised_about
        scale = 1.0 + float(np.max(np.abs(about), initial=0.0))
        if recorded is None or np.max(np.abs(recorded - about), initial=0.0) > ABOUT_CHECK * scale:
            raise GradientError(
                f"step {record.step}: its closest-approach rows were linearised about a point "
                f"the backward pass does not chain (a Coulomb fixed point that re-linearised "
                f"its rows, or an unknown pass rule)")


def _pass_adjoint(record: StepTape, qp: StepQP, solution: StepSolution, a_x: FloatArray,
                  last: bool, found: tuple[ActiveSet, bool],
                  ) -> tuple[QPAdjoint, FrictionAdjoint | None, int, ActiveSet]:
    """One pass's adjoint (a Coulomb step's fixed point for the last), its weak rows.

    ``found``: its active set and whether it was guessed (:func:`_active`).
    """
    active, guessed = found
    friction, weak = None, 0
    if last and record.forces is not None and qp.cones is not None:  # the fixed point
        adjoint, friction, weak = coulomb_adjoint(
            qp, unshifted_target(qp, record.forces), solution.x, solution.ineq_dual, active,
            record.forces, a_x, record.step, solution.eq_dual)
    else:
        adjoint = qp_adjoint(qp, solution.x, solution.ineq_dual, active, a_x, record.step,
                             solution.eq_dual)
    return (adjoint, friction,
            weak_rows(qp, solution.x, solution.ineq_dual, active) + int(guessed) + weak, active)


def _switches(tape: GradientTape, qp: StepQP, active: ActiveSet) -> int:
    """Tight rows at a switch of their right side's formula (one-sided there).

    ``start``: the speculative/Baumgarte switch at a gap of 0
    (:func:`~wuerfel_cvx.gradients.adjoint.gap_switch_rows`).  Closest approach: the ramp's
    switch at a start gap of ``-dt u`` (``u`` the push-out speed), where its rate turns
    from ``-phi_0 / dt`` to ``u``.
    """
    if not _closest_approach(tape):
        return gap_switch_rows(qp, active, row_contacts(qp))
    tight = np.concatenate([active.lower, active.upper]).astype(np.int64)
    if not tight.size:
        return 0
    push = float(getattr(tape.formulation, "push_speed", 1.0))
    contact = approach_contacts(qp)[tight]
    return int(np.count_nonzero(np.abs(qp.contacts.gap[contact] + tape.dt * push)
                                <= GAP_SWITCH))


def _rows_back(tape: GradientTape, qp: StepQP, x: FloatArray, points: FloatArray,
               adjoint: QPAdjoint, adjoints: _Adjoints, approach: ContactRows | None,
               ) -> FloatArray:
    """The tight rows' part: ``dL/dG_r = z_r a_x - a_nu,r x``, ``dL/dh_r = a_nu,r``.

    Carried to the contacts' bodies' coordinates and friction coefficients; returns the
    adjoint of the pass's linearisation point ``(u_x, u_y, omega)`` per body (zeros for
    rows linearised at the step's start).
    """
    model, tight = tape.model, adjoint.rows
    multiplier, row_adjoint = adjoint.row_multiplier, adjoint.row_adjoint
    about = np.zeros(3 * model.n_boxes)
    if approach is not None:  # closest-approach rows, found for the whole run at once
        rows = approach
    else:
        beta = float(getattr(tape.formulation, "beta", 0.2))
        rows = contact_rows(model, points, qp.contacts, qp, tape.dt, beta)
    contact = rows.contact[tight]
    edge_bodies, point_bodies = qp.contacts.edge_body[contact], qp.contacts.point_body[contact]
    moving, columns = body_columns(model, edge_bodies, point_bodies)
    coefficient = np.where(moving, multiplier[:, None] * adjoint.unknowns_adjoint[columns]
                           - row_adjoint[:, None] * x[columns], 0.0)
    local = row_adjoint[:, None] * rows.rhs.grad[tight]
    for column, entry in enumerate(rows.edge_entries + rows.point_entries):
        local += coefficient[:, column, None] * entry.grad[tight]
    _scatter(model, edge_bodies, point_bodies, local[:, :len(LOCAL)], adjoints)
    if local.shape[1] > len(LOCAL):  # the linearisation point's columns, edge's then point's
        np.add.at(about, columns.T[moving.T], local[:, len(LOCAL):].T[moving.T])
    return about


def _slips_back(tape: GradientTape, record: StepTape, points: FloatArray,
                friction: FrictionAdjoint, unknowns_adjoint: FloatArray,
                adjoints: _Adjoints, corners: bool = False) -> None:
    """A ``coulomb`` step's slip rows and coefficients (:mod:`~wuerfel_cvx.gradients.adjoint`).

    ``dL/dS_c = slip_unknowns_c a_x - slip_solution_c x`` and ``dL/dmu_c``, carried to the
    contacts' local inputs by the slip rows' derivatives: in body columns (``rigid``) or,
    with ``corners``, in corner columns (``velocity``).
    """
    model, qp, x = tape.model, record.qp, record.solution.x
    involved = np.flatnonzero((friction.slip_unknowns != 0.0) | (friction.slip_solution != 0.0)
                              | (friction.mu != 0.0))
    if not involved.size:
        return
    if corners:
        blocks, mu = corner_slips(model, points, qp.contacts)
        local = friction.mu[involved, None] * mu.grad[involved] + corner_local(
            model, blocks, involved, friction.slip_unknowns[involved],
            friction.slip_solution[involved], unknowns_adjoint, x)
        _scatter(model, qp.contacts.edge_body[involved], qp.contacts.point_body[involved],
                 local, adjoints)
        return
    rows = slip_rows(model, points, qp.contacts)
    local = friction.mu[involved, None] * rows.mu.grad[involved]
    for bodies, entries in ((qp.contacts.edge_body[involved], rows.edge_entries),
                            (qp.contacts.point_body[involved], rows.point_entries)):
        moving = bodies < model.n_boxes
        column = 3 * np.where(moving, bodies, 0)
        for axis, entry in enumerate(entries):
            coefficient = np.where(moving, friction.slip_unknowns[involved]
                                   * unknowns_adjoint[column + axis]
                                   - friction.slip_solution[involved] * x[column + axis], 0.0)
            local += coefficient[:, None] * entry.grad[involved]
    _scatter(model, qp.contacts.edge_body[involved], qp.contacts.point_body[involved], local,
             adjoints)


def _scatter(model: Model, edge_bodies: IntArray, point_bodies: IntArray,
             local: FloatArray, adjoints: _Adjoints) -> None:
    """Add per-contact derivatives ``(m, len(LOCAL))`` to the moving bodies' adjoints."""
    edge, point = (np.flatnonzero(bodies < model.n_boxes) for bodies in (edge_bodies,
                                                                          point_bodies))
    body = np.concatenate([edge_bodies[edge], point_bodies[point]])  # the edges' first
    for target, edge_column, point_column in (
            (adjoints.center[:, 0], 0, 3), (adjoints.center[:, 1], 1, 4),  # views: in place
            (adjoints.angle, 2, 5),
            (adjoints.friction, LOCAL.index("edge_friction"), LOCAL.index("point_friction"))):
        np.add.at(target, body, np.concatenate([local[edge, edge_column],
                                                local[point, point_column]]))


__all__ = ["GradientError", "checked_names", "gradient"]
