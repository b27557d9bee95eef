"""Solving a step QP in units that keep its data below a fixed magnitude.

A step QP (:mod:`wuerfel_cvx.formulations.qp`) in unknowns ``x``::

    min sum w (x - t)^2 + |F (x - t)|^2   s.t.  E x = e,  h <= G x <= u

is, with ``x = s y`` for a number ``s > 0``, the QP in ``y``::

    min sum w (y - t/s)^2 + |F (y - t/s)|^2   s.t.  E y = e/s,  h/s <= G y <= u/s

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
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .formulations.qp import StepQP
from .geometry import FloatArray

SCALE_LIMIT = 2.0**10
"""Largest magnitude (units of the unknowns: m/s, or m/s^2 for accelerations) of a step QP's
targets and right-hand sides that is solved as it is.  Larger data are solved in units of
``s`` times the original (:func:`unknowns_scale`).  Interior-point solvers (CLARABEL) were
seen to report ``infeasible`` on feasible QPs from data of about 1e5 on; 2^10 is two
orders below that and above the magnitudes of ordinary scenes (see
``docs/false-infeasible.md``)."""


def data_magnitude(qp: StepQP) -> float:
    """The largest finite ``|t|``, ``|e|``, ``|h|``, ``|u|`` of ``qp`` (0 if none)."""
    arrays: list[FloatArray] = [qp.target, qp.eq_rhs, qp.ineq_rhs]
    if qp.ineq_upper is not None:
        arrays.append(qp.ineq_upper[qp.upper_rows])
    return max((float(np.max(np.abs(values))) for values in arrays if np.size(values)),
               default=0.0)


def unknowns_scale(qp: StepQP) -> float:
    """The power of two ``s >= 1`` of :func:`scaled_qp`: 1 up to :data:`SCALE_LIMIT`.

    Else the smallest power of two with ``data_magnitude(qp) / s <= SCALE_LIMIT``.
    Non-finite data give 1 (they are rejected before any solver runs).
    """
    magnitude = data_magnitude(qp)
    if not magnitude > SCALE_LIMIT or not math.isfinite(magnitude):
        return 1.0
    mantissa, exponent = math.frexp(magnitude / SCALE_LIMIT)  # ratio = mantissa 2^exponent
    power = exponent - 1 if mantissa == 0.5 else exponent  # 0.5 <= mantissa < 1
    return math.ldexp(1.0, power)


def scaled_qp(qp: StepQP, scale: float) -> StepQP:
    """The QP in unknowns ``y = x / scale`` (``qp`` itself when ``scale`` is 1)."""
    if scale == 1.0:
        return qp
    upper = None if qp.ineq_upper is None else qp.ineq_upper / scale  # +inf stays +inf
    return dataclasses.replace(qp, target=qp.target / scale, eq_rhs=qp.eq_rhs / scale,
                               ineq_rhs=qp.ineq_rhs / scale, ineq_upper=upper,
                               _declared=None)
