"""Solving a step QP in units that keep its data below a fixed magnitude.

A step QP (:mod:`wuerfel_cvx.formulations.qp`) in unknowns ``x``::

    min sum w (x - t)^2 + |F (x - t)|^2 + l' x   s.t.  E x = e,  h <= G x <= u

is, with ``x = s y`` for a number ``s > 0``, the QP in ``y``::

    min sum w (y - t/s)^2 + |F (y - t/s)|^2 + (l/s)' y   s.t.  E y = e/s,  h/s <= G y <= u/s

(the objective divided by ``s^2``, which leaves the minimiser alone).  Its weights and
matrices are the original ones, so its structure
(:meth:`~wuerfel_cvx.formulations.qp.StepQP.structure`) is too, and a compiled problem or a
direct backend serves both.  Its multipliers are the original ones divided by ``s``: the
scaled stationarity ``2 W (y - t/s) + ... + E' y_s - G' z_s = 0`` is the original one
divided by ``s`` when ``y_s = y / s`` and ``z_s = z / s``.  So a solution of the scaled QP
maps back as ``x = s y``, ``y = s y_s``, ``z = s z_s``.

``s`` is a power of two: dividing by it and multiplying back are exact in binary floating
point (outside the subnormal range), so scaling adds no round-off of its own, and a QP
whose data are at most :data:`SCALE_LIMIT` in magnitude has ``s = 1`` and is handed to the
solver unchanged, bit for bit.  Only larger data are scaled, by the smallest power of two
that brings their largest magnitude to at most :data:`SCALE_LIMIT`.  Data are never scaled
up: below the limit the solvers' absolute tolerances and the KKT check's ``1 + |data|``
scales already agree.

The objective's weights (masses, kg, and moments of inertia, kg m^2) get the same treatment
from below.  Multiplying them by ``c`` (and ``F`` by ``sqrt(c)``, a linear cost ``l`` by ``c``:
the whole objective times ``c``) leaves the minimiser alone
and multiplies every multiplier by ``c``.  A scene of light bodies (a card of 0.8 g) has
multipliers (impulses, N s) of order ``m g dt``, far below 1, where the solvers' absolute
tolerances and the ``1 + |data|`` scales let a complementarity product of ``1e-10`` hide a
contact velocity error of ``1e-5`` m/s.  So a QP whose largest weight is below
:data:`WEIGHT_FLOOR` is solved with its weights multiplied by the smallest power of four
that brings the largest to at least the floor (:func:`weights_scale`); a power of four
keeps ``c`` and ``sqrt(c)`` powers of two, exact.  Weights at or above the floor are never
scaled, so QPs of ordinary masses reach the solver bit for bit as they are.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..formulations.qp import StepQP
from ..scenes.geometry import FloatArray

SCALE_LIMIT = 2.0**10
"""Largest magnitude (units of the unknowns: m/s, or m/s^2 for accelerations) of a step QP's
targets and right-hand sides that is solved as it is.  Larger data are solved in units of
``s`` times the original (:func:`unknowns_scale`).  Interior-point solvers (CLARABEL) were
seen to report ``infeasible`` on feasible QPs from data of about 1e5 on; 2^10 is two
orders below that and above the magnitudes of ordinary scenes (see
``docs/false-infeasible.md``)."""


WEIGHT_FLOOR = 0.25
"""Smallest largest objective weight (kg, or kg m^2) solved as it is: a corner of a 1 kg
square.  Lighter QPs are solved with weights scaled up to at least this
(:func:`weights_scale`)."""


def data_magnitude(qp: StepQP) -> float:
    """The largest finite ``|t|``, ``|e|``, ``|h|``, ``|u|`` of ``qp`` (0 if none).

    Finite data only: NaN, where the data hold any, may be returned in place of a number
    (such a QP is rejected before it is scaled).
    """
    arrays: list[FloatArray] = [qp.target, qp.eq_rhs, qp.ineq_rhs]
    if qp.ineq_upper is not None:
        arrays.append(qp.ineq_upper[qp.upper_rows])
    values = np.concatenate(arrays)  # one reduction: per-call overhead outweighs the work
    return float(np.abs(values).max()) if values.size else 0.0


def unknowns_scale(qp: StepQP) -> float:
    """The power of two ``s >= 1`` of :func:`scaled_qp`: 1 up to :data:`SCALE_LIMIT`.

    Else the smallest power of two with ``data_magnitude(qp) / s <= SCALE_LIMIT``.
    Non-finite data give 1 (they are rejected before any solver runs).
    """
    return scale_of_magnitude(data_magnitude(qp))


def scale_of_magnitude(magnitude: float) -> float:
    """:func:`unknowns_scale` of a QP whose :func:`data_magnitude` is ``magnitude``."""
    if not magnitude > SCALE_LIMIT or not math.isfinite(magnitude):
        return 1.0
    mantissa, exponent = math.frexp(magnitude / SCALE_LIMIT)  # ratio = mantissa 2^exponent
    power = exponent - 1 if mantissa == 0.5 else exponent  # 0.5 <= mantissa < 1
    return math.ldexp(1.0, power)


def weights_scale(qp: StepQP) -> float:
    """The power of four ``c >= 1`` the weights are multiplied by (:func:`scaled_qp`).

    1 when the largest weight is at least :data:`WEIGHT_FLOOR` (or not positive and
    finite); else the smallest power of four with ``max(w) c >= WEIGHT_FLOOR``.
    """
    return scale_of_weight(float(qp.weights.max()) if qp.weights.size else 0.0)


def scale_of_weight(largest: float) -> float:
    """:func:`weights_scale` of a QP whose largest weight is ``largest`` (kg, or kg m^2)."""
    if not 0.0 < largest < WEIGHT_FLOOR:
        return 1.0
    mantissa, exponent = math.frexp(WEIGHT_FLOOR / largest)  # ratio = mantissa 2^exponent
    power = exponent - 1 if mantissa == 0.5 else exponent  # smallest 2^power >= ratio
    return math.ldexp(1.0, power + power % 2)  # rounded up to an even power: 4^k


def scaled_qp(qp: StepQP, scale: float, weight_scale: float = 1.0) -> StepQP:
    """The QP in unknowns ``y = x / scale``, weights times ``weight_scale``.

    ``qp`` itself when both are 1.  ``weight_scale`` must be a power of four (its square
    root scales ``F``; a linear cost ``l`` becomes ``weight_scale l / scale``, the objective
    being multiplied by ``weight_scale / scale^2``); the multipliers of the result are
    ``weight_scale / scale`` times those of ``qp``.
    """
    if scale == 1.0 and weight_scale == 1.0:
        return qp
    upper = None if qp.ineq_upper is None else qp.ineq_upper / scale  # +inf stays +inf
    factor = None if qp.cost_factor is None else qp.cost_factor * math.sqrt(weight_scale)
    linear = None if qp.linear is None else qp.linear * (weight_scale / scale)  # exact
    return dataclasses.replace(qp, weights=qp.weights * weight_scale, cost_factor=factor,
                               linear=linear,
                               target=qp.target / scale, eq_rhs=qp.eq_rhs / scale,
                               ineq_rhs=qp.ineq_rhs / scale, ineq_upper=upper)
