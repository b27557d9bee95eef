"""The ``velocity`` step's numbers in corner coordinates, with derivatives.

The ``velocity`` formulation (:class:`~wuerfel_cvx.formulations.velocity.VelocityFormulation`,
rigid position update, fixed tables) poses its step QP in the corner velocities ``v+``
``(8 n,)``: weights ``m_q = M / 4`` per corner coordinate, target ``v + dt g``, the rods'
equalities ``(d / l) . (v+_i - v+_j) = -(beta / dt) C / l`` (``d = p_i - p_j``, ``C = (|d|^2 -
l^2) / 2``), and contact rows in corner columns.  Its states are rigid: the corners are an
exact rectangle and the corner velocities a rigid motion, ``v_q = u + omega rot90(f_q)``,
``f_q = R(theta) r_q`` (the advance, :func:`~wuerfel_cvx.formulations.motion.rigid_step`,
makes them so).  The backward pass therefore carries the same state adjoint as ``rigid``'s,
per body ``(a_c, a_theta, a_u, a_omega)`` (:mod:`~wuerfel_cvx.gradients.backward`), and
differentiates the corner-space QP and advance with respect to those coordinates:

* *the fit* ``J``: a box's corner velocities ``w`` describe the motion of centre velocity
  ``mean w`` and spin ``sum rot90(f_q) . w_q / S`` (``S = sum |f_q|^2``, m^2); its
  transpose takes a body adjoint ``(a_u, a_omega)`` to ``a_u / 4 + a_omega rot90(f_q) / S``
  per corner, and ``d/dtheta`` of the spin is ``-sum f_q . w_q / S`` (:class:`CornerFit`);
* *the advance* ``c' = c + dt mean(v+)``, ``theta' = theta + dt omega(v+)``, ``(u', omega') =
  J v+``: ``dL/dv+ = J' (dt a_c' + a_u', dt a_theta' + a_omega')``, and ``a_theta`` takes the
  spin's dependence on the fitted angle;
* *the objective*: ``dL/dv = dL/dt`` to ``a_u = sum_q``, ``a_omega = sum_q . rot90(f_q)`` and
  ``a_theta -= omega sum_q . f_q``; ``dL/dg = dt sum_q``; ``dL/dM = sum dL/dw / 4``;
* *the rods*: on a rigid state ``C = 0`` and stays 0 under every rigid change (``dC = d . dd
  = 0``), so the right sides contribute nothing; a turn ``dtheta`` turns ``d`` by
  ``rot90(d) dtheta``, so with ``dL/dE_r = -(y_r a_x + a_y,r x)`` (the adjoint's equality
  part, :class:`~wuerfel_cvx.gradients.adjoint.QPAdjoint`) the body's ``a_theta`` takes
  ``sum_r (dL/dE_r,i - dL/dE_r,j) . rot90(d_r) / l_r`` (:func:`rods_back`);
* *start rows* (``velocity-baumgarte``): three corner blocks per row, ``g + sigma mu s``,
  differentiated as rigid's (:func:`~wuerfel_cvx.gradients.rigid.corner_rows`);
* *closest-approach rows* (``velocity``): a row is ``N J + sigma mu s``, ``N`` the body-column
  row ``rigid`` poses for the same motion (``velocity``'s own rows in body columns,
  :func:`approach_view`, differentiated by rigid's complex steps,
  :func:`~wuerfel_cvx.gradients.rigid.approach_rows_of`) and ``s`` the slip blocks.  With
  ``w_r = z_r a_x - a_nu,r x`` (corner space), ``w_r . d(N J) = (J w_r) . dN + N_omega .
  dJ w_r``: rigid's row adjoint with ``J x`` and ``J a_x``, plus a turn of the fit
  (:func:`fit_turns`); the linearisation point's adjoint comes back through ``J'``.

* ``coulomb`` friction: the fixed point's conditions
  (:func:`~wuerfel_cvx.gradients.adjoint.coulomb_adjoint`) hold in any unknowns, the rods'
  equalities among them; its slip rows ``s`` are corner blocks
  (:func:`~wuerfel_cvx.gradients.rigid.corner_slips`).

Every recomputed row is checked against the recorded QP (:func:`check_rows`).  What is not
covered: heavy tables (``table_mass``) and the linear position update (refused by
:func:`~wuerfel_cvx.gradients.tape.check_supported`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._sparse import empty_rows
from ..formulations.motion import body_motion
from ..formulations.qp import StepQP, declare_qp
from ..formulations.rows import body_rows
from ..formulations.velocity import closest_approach, rows_along
from ..scenes.geometry import FloatArray
from ..step.model import IntArray, Model
from .adjoint import QPAdjoint
from .rigid import ROW_CHECK, ContactRows, CornerRows
from .tape import GradientError


@dataclass(frozen=True)
class CornerFit:
    """The fit ``J`` of a rigid state's boxes (the module docstring)."""

    fitted: FloatArray
    """Fitted corner offsets ``f`` ``(n, 4, 2)`` (m) from the centres."""
    spread: FloatArray
    """``S = sum_q |f_q|^2`` ``(n,)`` (m^2)."""

    @classmethod
    def of(cls, model: Model, points: FloatArray) -> CornerFit:
        """The fit of the boxes whose corners are ``points`` ``(4 n, 2)`` (m).

        The forward pass's own (:func:`~wuerfel_cvx.formulations.motion.body_motion`).
        """
        fitted = body_motion(model, points, np.zeros_like(points)).fitted[:model.n_boxes]
        return cls(fitted, np.sum(fitted * fitted, axis=(1, 2)))

    def to_bodies(self, corner: FloatArray) -> FloatArray:
        """``J w``: centre velocity and spin ``(3 n,)`` of corner velocities ``w`` ``(8 n,)``."""
        w = corner.reshape(-1, 4, 2)
        spin = np.sum(self.fitted[..., 0] * w[..., 1] - self.fitted[..., 1] * w[..., 0],
                      axis=1) / self.spread
        return np.concatenate([w.mean(axis=1), spin[:, None]], axis=1).ravel()

    def to_corners(self, body: FloatArray) -> FloatArray:
        """``J' a``: a body adjoint ``(3 n,)`` as a corner adjoint ``(8 n,)``."""
        a = body.reshape(-1, 3)
        turned = np.stack([-self.fitted[..., 1], self.fitted[..., 0]], axis=-1)
        return np.asarray(0.25 * a[:, None, :2] + (a[:, 2] / self.spread)[:, None, None]
                          * turned, dtype=np.float64).ravel()

    def turns(self, spin_adjoint: FloatArray, corner: FloatArray) -> FloatArray:
        """``a_omega d(omega)/d(theta)`` ``(n,)`` of the spin of ``corner`` ``(8 n,)``."""
        w = corner.reshape(-1, 4, 2)
        return np.asarray(-spin_adjoint * np.sum(self.fitted * w, axis=(1, 2)) / self.spread,
                          dtype=np.float64)


@dataclass(frozen=True)
class ObjectiveAdjoint:
    """What the objective's adjoint makes of the state at the step's start and the scene."""

    velocity: FloatArray
    """``a_u`` ``(n, 2)``."""
    angular_velocity: FloatArray
    """``a_omega`` ``(n,)``."""
    angle: FloatArray
    """Added to ``a_theta`` ``(n,)`` (the state's velocities turn with the body)."""
    gravity: FloatArray
    """Added to ``dL/dg`` ``(2,)``."""
    mass: FloatArray
    """Added to ``dL/dM`` ``(n,)``."""


def objective_back(fit: CornerFit, model: Model, qp: StepQP, target: FloatArray,
                   weights: FloatArray, dt: float) -> ObjectiveAdjoint:
    """The objective's part: ``dL/dt`` (``target``) and ``dL/dw`` (``weights``), ``(8 n,)``."""
    n = model.n_boxes
    velocities = qp.target.reshape(-1, 2)[:4 * n] - dt * model.gravity
    spin = fit.to_bodies(velocities.ravel())[2::3]
    per_corner = target.reshape(n, 4, 2)
    turned = np.stack([-fit.fitted[..., 1], fit.fitted[..., 0]], axis=-1)
    return ObjectiveAdjoint(
        velocity=per_corner.sum(axis=1),
        angular_velocity=np.sum(per_corner * turned, axis=(1, 2)),
        angle=-spin * np.sum(per_corner * fit.fitted, axis=(1, 2)),
        gravity=dt * per_corner.sum(axis=(0, 1)),
        mass=0.25 * weights.reshape(n, 8).sum(axis=1))


def rods_back(model: Model, points: FloatArray, x: FloatArray,
              adjoint: QPAdjoint) -> FloatArray:
    """The rods' part of ``a_theta`` ``(n,)`` (the module docstring)."""
    rods = model.rods
    if adjoint.eq_multiplier.size != len(rods):
        raise GradientError("the step QP's equalities are not the model's rods (heavy "
                            "tables are not covered)")
    d = points[rods[:, 0]] - points[rods[:, 1]]
    turned = np.stack([-d[:, 1], d[:, 0]], axis=1) / model.rod_lengths[:, None]
    a_x, values = adjoint.unknowns_adjoint.reshape(-1, 2), x.reshape(-1, 2)
    y, a_y = adjoint.eq_multiplier[:, None], adjoint.eq_adjoint[:, None]
    difference = -(y * (a_x[rods[:, 0]] - a_x[rods[:, 1]])
                   + a_y * (values[rods[:, 0]] - values[rods[:, 1]]))
    angle = np.zeros(model.n_boxes)
    np.add.at(angle, rods[:, 0] // 4, np.sum(difference * turned, axis=1))
    return angle


def corner_local(model: Model, rows: CornerRows, picked: IntArray, multiplier: FloatArray,
                 row_adjoint: FloatArray, unknowns_adjoint: FloatArray,
                 x: FloatArray) -> FloatArray:
    """``dL/d(local)`` ``(t, 8)`` of rows ``picked`` among ``rows``'s rows.

    ``w_r . dG_r + a_nu,r dh_r`` with ``w_r = z_r a_x - a_nu,r x`` on each block's corner
    (``z`` the ``multiplier``, ``a_nu`` the ``row_adjoint`` of each picked row, ``a_x`` the
    ``unknowns_adjoint``); for a ``coulomb`` step's slip rows ``2 lambda_t`` and ``a_s``.
    """
    multiplier, row_adjoint = multiplier[:, None], row_adjoint[:, None]
    local = row_adjoint * rows.rhs.grad[picked]
    a_x, values = unknowns_adjoint.reshape(-1, 2), x.reshape(-1, 2)
    for index, block in zip(rows.corners, rows.blocks, strict=True):
        corner = index[picked]
        moving = (corner < model.n_points)[:, None]
        safe = np.where(moving[:, 0], corner, 0)
        w = np.where(moving, multiplier * a_x[safe] - row_adjoint * values[safe], 0.0)
        local += w[:, 0, None] * block[0].grad[picked] + w[:, 1, None] * block[1].grad[picked]
    return np.asarray(local, dtype=np.float64)


def fit_turns(model: Model, fit: CornerFit, view: ContactRows, normal: IntArray,
              contacts_bodies: tuple[IntArray, IntArray], adjoint: QPAdjoint,
              x: FloatArray) -> FloatArray:
    """``N_omega . dJ w_r`` of the tight closest-approach rows: their part of ``a_theta``.

    ``normal`` each tight row's normal row of ``view``; ``contacts_bodies`` its edge and
    point bodies.
    """
    angle = np.zeros(model.n_boxes)
    a_x, values = adjoint.unknowns_adjoint.reshape(-1, 4, 2), x.reshape(-1, 4, 2)
    multiplier, row_adjoint = adjoint.row_multiplier, adjoint.row_adjoint
    for bodies, entries in zip(contacts_bodies, (view.edge_entries, view.point_entries),
                               strict=True):
        moving = np.flatnonzero(bodies < model.n_boxes)
        body = bodies[moving]
        w = (multiplier[moving, None, None] * a_x[body]
             - row_adjoint[moving, None, None] * values[body])
        turn = -np.sum(fit.fitted[body] * w, axis=(1, 2)) / fit.spread[body]
        np.add.at(angle, body, entries[2].value[normal[moving]] * turn)
    return angle


def approach_view(model: Model, points: FloatArray, qp: StepQP, push_speed: float,
                  dt: float) -> StepQP:
    """A closest-approach pass's normal rows ``N`` in body columns, as ``rigid`` poses them.

    ``velocity``'s own rows (:func:`~wuerfel_cvx.formulations.velocity.rows_along` along
    ``qp.linearised_about``, its corner velocities) times the corner map, without cones; the
    view's linearisation point stays the corner velocities.
    """
    about = qp.linearised_about
    if about is None:
        raise GradientError("a closest-approach pass without its linearisation point")
    approach = (qp.approach if qp.approach is not None
                else closest_approach(model, points, qp.contacts, about, dt, push_speed))
    rows = rows_along(model, qp.contacts, approach)
    size = 3 * model.n_boxes
    return declare_qp(np.ones(size), np.zeros(size), empty_rows(size), np.zeros(0),
                      body_rows(rows.matrix, points), rows.rhs, qp.contacts,
                      linearised_about=about, approach=approach)


def check_rows(model: Model, qp: StepQP, fit: CornerFit, view: ContactRows | None,
               normal: IntArray, rows: CornerRows) -> None:
    """Refuse a step whose recomputed corner rows are not the recorded QP's.

    Each row ``r``: ``view``'s row ``normal[r]`` through the fit (``N J``; none for start
    rows), plus ``rows``'s blocks.  Relative to the rows' largest entry (:data:`ROW_CHECK`).
    """
    dense = np.zeros((qp.n_inequalities, qp.n_variables))
    every = np.arange(qp.n_inequalities)
    if view is not None:
        for bodies, entries in ((qp.contacts.edge_body, view.edge_entries),
                                (qp.contacts.point_body, view.point_entries)):
            body = bodies[view.contact[normal]]
            moving = np.flatnonzero(body < model.n_boxes)
            row_body = np.stack([entry.value[normal[moving]] for entry in entries], axis=1)
            corner = _through_fit(row_body, fit, body[moving])
            columns = 8 * body[moving, None] + np.arange(8)
            np.add.at(dense, (moving[:, None], columns), corner)
    for index, block in zip(rows.corners, rows.blocks, strict=True):
        unknown = index < model.n_points
        for axis in range(2):
            np.add.at(dense, (every[unknown], 2 * index[unknown] + axis),
                      block[axis].value[unknown])
    recorded = qp.ineq_matrix.toarray()
    scale = 1.0 + float(np.max(np.abs(recorded), initial=0.0))
    if recorded.shape != dense.shape or (recorded.size and
                                         np.max(np.abs(recorded - dense)) > ROW_CHECK * scale):
        raise GradientError("the recomputed corner rows differ from the recorded step QP's: "
                            "the backward pass does not know this formulation's options")


def _through_fit(rows: FloatArray, fit: CornerFit, body: IntArray) -> FloatArray:
    """Body-column entries ``(t, 3)`` of bodies ``body`` as corner entries ``(t, 8)``: ``N J``."""
    f = fit.fitted[body]
    turned = np.stack([-f[..., 1], f[..., 0]], axis=-1)
    return np.asarray(0.25 * rows[:, None, :2] + (rows[:, 2] / fit.spread[body])[:, None, None]
                      * turned, dtype=np.float64).reshape(-1, 8)
