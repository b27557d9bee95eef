"""Gradients through a simulation: implicit differentiation of each verified step QP.

A step here is a convex QP whose answer is polished on its active set and checked against
its KKT conditions; on that active set the answer solves one linear system, the reduced KKT
system, so its derivative with respect to the QP's numbers follows from one more solve with
the same (symmetric) matrix: the adjoint (:mod:`wuerfel_cvx.gradients.adjoint`).  A run
recorded with ``gradients=True`` keeps each step's QP and answer
(:mod:`wuerfel_cvx.gradients.tape`); :meth:`Trajectory.gradient
<wuerfel_cvx.trajectory.Trajectory.gradient>` propagates a loss's gradient backwards through
the steps (:mod:`wuerfel_cvx.gradients.backward`), each step's QP numbers differentiated
with respect to the state and the parameters exactly (:mod:`wuerfel_cvx.gradients.rigid`).

What is covered: the ``rigid`` formulation, frictionless contacts, ``ccp`` friction and
``coulomb`` friction (through its converged fixed point:
:mod:`wuerfel_cvx.gradients.adjoint`), with respect to the initial centres, angles,
velocities and angular velocities, the bodies' friction coefficients and masses, and
gravity.  What is not, and why:

* ``velocity`` (the default) and ``velocity-baumgarte``: their rows come from Gauss-Newton
  passes linearised about the previous pass's answer (closest approach), and their rods are
  equalities in corner velocities; the chain through the passes is not written yet.
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
