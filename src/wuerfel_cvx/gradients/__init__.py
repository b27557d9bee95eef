"""Gradients through a simulation: implicit differentiation of each verified step QP.

A step here is a convex QP whose answer is polished on its active set and checked against
its KKT conditions; on that active set the answer solves one linear system, the reduced KKT
system, so its derivative with respect to the QP's numbers follows from one more solve with
the same (symmetric) matrix: the adjoint (:mod:`wuerfel_cvx.gradients.adjoint`).  A run
recorded with ``gradients=True`` keeps each step's QP and answer
(:mod:`wuerfel_cvx.gradients.tape`); :meth:`Trajectory.gradient
<wuerfel_cvx.trajectory.Trajectory.gradient>` propagates a loss's gradient backwards through
the steps (:mod:`wuerfel_cvx.gradients.backward`), each step's QP numbers differentiated
with respect to the state and the parameters exactly (:mod:`wuerfel_cvx.gradients.rigid`,
and in corner coordinates :mod:`wuerfel_cvx.gradients.velocity`).

What is covered: the ``rigid`` formulation, frictionless contacts, ``ccp`` friction and
``coulomb`` friction (through its converged fixed point:
:mod:`wuerfel_cvx.gradients.adjoint`), with respect to the initial centres, angles,
velocities and angular velocities, the bodies' friction coefficients and masses, and
gravity; its rows linearised at the step's start or at closest approach
(``RigidFormulation(linearisation="closest-approach")``).  The ``velocity`` formulation
likewise (``velocity`` and ``velocity-baumgarte``), with the same friction models: its
corner-velocity unknowns held by rods, differentiated through the fit that makes its rigid
states' corner velocities a body's motion (:mod:`wuerfel_cvx.gradients.velocity`).

*Closest-approach rows and their passes: what is differentiated.*  Each pass's rows are
functions of the start coordinates, the friction coefficients and the pass's linearisation
point ``about``, also through the closest-approach time ``tau*`` as the forward pass
computes it (:func:`~wuerfel_cvx.gradients.rigid.approach_rows`).  A step of several
Gauss-Newton passes is differentiated as the computation it was, not as the passes' fixed
point (which the forward pass stops short of, within its gap tolerance): pass 1 is
linearised about the target ``(u + dt g, omega)``, pass 2 about pass 1's answer, pass
``q >= 3`` about the mean of pass ``q - 1``'s answer and point, and the adjoint of each
pass's ``about`` is carried to those (:mod:`~wuerfel_cvx.gradients.backward`).  A ``coulomb``
step whose fixed point re-linearised its rows (passes interleaved with friction problems)
is refused.  What is not covered, and why:

* ``velocity`` with heavy tables or the linear position update: heavy tables add unknowns
  and equalities besides the rods; the linear update leaves the rigid states the
  corner-space derivatives rely on.
* ``seed`` formulations: acceleration-level, no friction; not covered.

Where the active set changes, the derivative is one-sided: the backward pass holds the
active set of each step's polished answer, which is the derivative from the side the
answer lies on, and it reports the steps with weakly active rows (a multiplier or a slack
near zero) as ``flagged_steps`` with their count in ``crossings``.  The contacts themselves
(which points face which edges) and each row's Baumgarte-or-speculative choice are
discrete and held likewise.
"""

from __future__ import annotations

from .backward import checked_names, gradient
from .tape import (
    SUPPORTED_FORMULATIONS,
    SUPPORTED_FRICTION_MODELS,
    WRT_NAMES,
    GradientError,
    GradientTape,
    StepTape,
    check_supported,
)

__all__ = ["SUPPORTED_FORMULATIONS", "SUPPORTED_FRICTION_MODELS", "WRT_NAMES",
           "GradientError", "GradientTape", "StepTape", "check_supported", "checked_names",
           "gradient"]
