"""Exact Coulomb friction by a fixed point of two convex problems (``friction_model="coulomb"``).

Staggered projections (Kaufman, Sueda, James and Pai 2008).  A step QP of ``velocity`` or
``rigid`` (:mod:`wuerfel_cvx.formulations.qp`) keeps its normal rows; its
:class:`~wuerfel_cvx.formulations.cone.ConeRows` give each contact's slip ``s = S x`` (m/s)
and coefficient ``mu``.  Two problems alternate:

*Contact QP*, the friction impulse ``lambda_t`` (N s, per contact, along its tangent) held
fixed as an external impulse.  The step QP's objective ``sum w (x - t)^2`` is twice the
kinetic-energy norm of the change of momentum (its stationarity ``W (x - t) = G' z / 2 -
E' y / 2`` makes ``z / 2`` the impulses), so an impulse ``S' lambda_t`` on the unknowns moves
its target to::

    t' = t + W^-1 S' lambda_t                                        (units of x)

and the QP with target ``t'`` has ``2 W (x - t) = G' z + 2 S' lambda_t - E' y``.  Its normal
rows' multipliers give the normal impulses ``lambda_n = sum_rows z / 2`` of each contact (both
closest-approach rows of a contact add to its impulse).

*Friction problem*, the normal impulses held fixed::

    minimise    sum w (x - t_n)^2 + 2 sum_c mu_c lambda_n,c |S_c x|
    subject to  E x = e                 t_n = t + W^-1 G' z / 2

``t_n`` the unknowns after the contact QP's normal impulses (rods re-solved by ``E x = e``):
convex, solved as a step QP (a slack per contact, :func:`~wuerfel_cvx.friction.problem.friction_qp`)
by the contact QPs' own solve function, its multipliers the friction impulse of maximal
dissipation in the cone ``|lambda_t| <= mu lambda_n``, and checked by its own residuals on
top of the QP's (:mod:`wuerfel_cvx.friction.problem`).

*Iteration.* From ``lambda_t = 0``, or from the impulses the same contacts had at the end of
the step before (``coulomb_warm_start``, :class:`FrictionMemory`): contact QP ->
``lambda_n`` -> friction problem -> ``lambda_t`` -> contact QP ..., until two successive
contact QPs agree to ``tolerance`` (:func:`_unchanged`) in either of two measures:

- how they move the bodies, ``sqrt(w) (x - t)`` (:attr:`ContactOutcome.motion`), unique
  where the impulses are not; its scale on a resting pile is one body's ``g dt``;
- their normal impulses summed over twin contacts (:attr:`ContactOutcome.twin_loads`), whose
  scale is the most loaded group's load.  Twins (:func:`_twin_groups`) are contacts whose
  normal rows are parallel (cards face to face): the split of a load among them is not
  unique, and the iteration can move it from one twin to the other for many friction
  problems while the bodies' motion has settled.

The motion alone asks a resting pile for ``tolerance * g dt`` of velocity, the twin loads
alone miss steps whose iteration contracts slowly; either suffices
(``reports/friction/coulomb-convergence.md``).

The impulse each contact QP holds is the friction problems' answers mixed by Anderson
acceleration (:class:`FrictionMixer`: inside the cones, safeguarded, and the plain answer
itself once the two contact QPs agree), which reaches the plain iteration's fixed point in
fewer friction problems. The closest-approach passes of ``velocity``
(:meth:`~wuerfel_cvx.formulations.velocity.VelocityFormulation.refine`) interleave: after
each contact QP its rows are re-linearised about its solution when the formulation asks so,
and the next contact QP takes the new rows with the current ``lambda_t``. The formulation's
pass limit counts the passes since ``lambda_t`` last changed, so that each friction impulse
has the passes a frictionless step has to meet the gap acceptance (a limit counted over the
whole iteration let steps be accepted by the limit, with penetrations beyond the bound). The
fixed point is converged only when the formulation also accepts the last contact QP's
solution; a settled impulse is held fixed through the formulation's further passes (a new
friction problem only if the contact QPs no longer agree), so the step's state, always the
last contact QP's, meets the formulation's gap acceptance (and with it the penetration
bound) exactly as a frictionless step does. After ``max_iterations`` friction problems
without convergence the step goes on with the last iterate: further passes, ``lambda_t``
fixed, until the formulation accepts; :attr:`CoulombStep.converged` says so.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import InputError
from ..formulations import Formulation, StepQP
from ..scenes.geometry import FloatArray
from ..solve.paths import StepSolution
from ..step.contacts import ContactIndex, Contacts
from ..step.model import IntArray, Model, State
from ..trajectory import NULLABLE_COLUMNS
from .forces import ContactForces
from .problem import (
    FrictionAnswer,
    QPSolve,
    friction_problem,
    normal_impulses,
    solve_friction,
)


@dataclass(frozen=True)
class CoulombStep:
    """What the fixed point solved for one step QP."""

    qp: StepQP
    """The last contact QP (its target shifted by the friction impulse it held fixed)."""
    solved: list[tuple[StepSolution, str]]
    """Every contact QP's solution and the run's own solver's status on it, in order."""
    answers: list[FrictionAnswer]
    """Every friction problem's answer, in order."""
    converged: bool
    forces: ContactForces
    """Per contact of :attr:`qp`: ``lambda_n`` from its solution, the ``lambda_t`` it held
    fixed, and the slip of its solution."""

    @property
    def iterations(self) -> int:
        """Friction problems solved (each followed by a contact QP)."""
        return len(self.answers)


def with_friction_impulse(qp: StepQP, friction: FloatArray) -> StepQP:
    """``qp`` with target ``t + W^-1 S' lambda_t``: the friction impulse held fixed."""
    if qp.cones is None:
        return qp
    shift = (qp.cones.slip.T @ friction) / qp.weights
    return dataclasses.replace(qp, target=qp.target + shift)


@dataclass(frozen=True)
class CoulombSettings:
    """The fixed point's limits (fields of the formulations, see their docstrings)."""

    max_iterations: int
    """Most friction problems per step QP."""
    tolerance: float
    """Converged when two successive contact QPs' motions, or their twin loads, differ by at
    most this times the largest (1, :func:`_unchanged`)."""
    memory: int = 5
    """Past iterates the Anderson acceleration of the friction impulse mixes
    (:class:`FrictionMixer`); 0: the plain iteration."""

    def __post_init__(self) -> None:
        if isinstance(self.max_iterations, bool) or not isinstance(self.max_iterations, int) \
                or self.max_iterations < 1:
            raise InputError(f"must be an integer >= 1, got {self.max_iterations}",
                             field="coulomb_max_iterations")
        if not (math.isfinite(self.tolerance) and self.tolerance > 0.0):
            raise InputError(f"must be a positive number, got {self.tolerance}",
                             field="coulomb_tolerance")


def fixed_point(formulation: Formulation, model: Model, state: State, qp: StepQP, dt: float,
                solve: QPSolve, tol: str | float, settings: CoulombSettings,
                initial: FloatArray | None = None) -> CoulombStep:
    """Iterate contact QP and friction problem from ``qp`` (see the module docstring).

    ``qp`` is the formulation's first pass, with ``qp.cones`` (its contacts with friction);
    ``solve`` solves the contact QPs and the friction problems' QPs alike (raising
    :class:`StepFailure` when no solver can), at tolerance ``tol``, which the friction
    problems' own check takes too.  ``initial`` is the friction impulse (N s) per contact of
    ``qp`` the first contact QP holds (zero when ``None``).
    """
    target = qp.target
    base = qp
    friction = np.zeros(len(qp.contacts)) if initial is None else np.asarray(initial, float)
    solved: list[tuple[StepSolution, str]] = []
    answers: list[FrictionAnswer] = []
    previous: ContactOutcome | None = None  # the contact QP the held friction was made of
    twins: IntArray | None = None  # base's _twin_groups, found once per set of rows
    mixer = FrictionMixer(settings.memory)
    linearisations, converged = 1, False  # passes since the friction impulse last changed
    while True:
        contact_qp = with_friction_impulse(base, friction)
        solved.append(solve(contact_qp, repeated=True))
        solution = solved[-1][0]
        refined = formulation.refine(model, state, contact_qp, solution.x, dt, linearisations)
        if contact_qp.cones is None:  # no contact with friction left: frictionless passes
            if refined is None:
                converged = True
                break
            linearisations += 1
            base, friction = dataclasses.replace(refined, target=target), \
                np.zeros(len(refined.contacts))
            mixer.reset()
            continue
        twins = _twin_groups(contact_qp) if twins is None else twins
        outcome = ContactOutcome.of(contact_qp, solution, target, twins)
        agree = previous is not None and _unchanged(outcome, previous, settings.tolerance)
        settled = agree and mixer.settled(settings.tolerance)
        if refined is None and (settled or len(answers) >= settings.max_iterations):
            converged = settled
            break
        # a settled impulse is held through the formulation's further passes
        new_impulse = not settled and len(answers) < settings.max_iterations
        if new_impulse:
            problem = friction_problem(contact_qp, solution, target)
            answers.append(solve_friction(problem, solve, tol))
            friction = mixer.next(friction, answers[-1].friction, problem.bound, plain=agree)
            previous = outcome
        # the next contact QP is the first pass of a new impulse, or the next pass of this one
        linearisations = 1 if new_impulse else linearisations + 1
        if refined is not None:
            base, twins = dataclasses.replace(refined, target=target), None
            if base.contacts is not contact_qp.contacts:
                mixer.reset()
                previous = None if previous is None else previous.without_loads()
            friction = _carried(friction, contact_qp.contacts, base.contacts)
    return CoulombStep(contact_qp, solved, answers, converged,
                       _forces(contact_qp, solution, friction))


SLOW = 0.5
"""A step that reduces the friction residual by less than this factor is slow; the mixer
accelerates after two slow steps in a row, and holds the plain answers before: most steps'
fixed points converge in one to three plain iterations (a slipping contact's impulse reaching
its cone's edge is exact in one), which Anderson's linear model would only approach."""


class FrictionMixer:
    """The friction impulse each contact QP holds: Anderson acceleration, safeguarded.

    The fixed point is ``lambda_t = g(lambda_t)``, ``g`` the friction problem's answer after
    the contact QP holding ``lambda_t``; the plain iteration holds ``g`` of the last impulse
    next.  Anderson's type-II mixing (Walker and Ni 2011) holds instead the combination of
    the last ``memory + 1`` answers whose residuals ``f = g(lambda_t) - lambda_t`` combine
    to the smallest (least squares over their differences), projected onto each contact's
    cone ``|lambda_t| <= mu lambda_n`` of the last normal impulses, so that every held
    impulse is one the cone admits.  Safeguard: a residual larger than the smallest in the
    history forgets the history and holds the plain answer.  An accelerated impulse is
    settled only when it lies within the tolerance (relative to the largest cone radius) of
    the plain answer, so that a converged step holds (to the tolerance) the friction
    problem's own answer, as the plain iteration does; near convergence (the two contact
    QPs agree) the plain answer is held, which settles it.
    """

    def __init__(self, memory: int) -> None:
        self.memory = memory
        self._held: list[FloatArray] = []
        self._answers: list[FloatArray] = []
        self._best = math.inf  # the smallest residual since the last reset (N s)
        self._slow = 0  # successive steps that reduced it by less than SLOW
        self._departure = 0.0  # |held - plain answer| of the last impulse chosen (N s)
        self._radius = 0.0  # the largest cone radius mu lambda_n of its answer (N s)

    def reset(self) -> None:
        """Forget the history (the contacts changed, or the safeguard)."""
        self._held, self._answers, self._best, self._slow = [], [], math.inf, 0

    def settled(self, tolerance: float) -> bool:
        """Whether the impulse held last is within ``tolerance`` of its plain answer."""
        return self._departure <= tolerance * self._radius

    def next(self, held: FloatArray, answer: FloatArray, bound: FloatArray, *,
             plain: bool = False) -> FloatArray:
        """The impulse (N s) to hold after ``answer`` = ``g(held)``, within ``|.| <= bound``.

        ``plain``: hold ``answer`` itself (and keep the history).
        """
        residual = float(np.linalg.norm(answer - held))
        last = (float(np.linalg.norm(self._answers[-1] - self._held[-1]))
                if self._answers and len(self._answers[-1]) == len(answer) else math.nan)
        if not residual <= min(last, self._best):  # NaN: the contacts changed
            self.reset()  # the safeguard: the last impulse did not reduce the residual
        self._best = min(self._best, residual)
        self._slow = self._slow + 1 if residual >= SLOW * last else 0
        self._held = [*self._held, held][-(self.memory + 1):]
        self._answers = [*self._answers, answer][-(self.memory + 1):]
        self._radius = _inf(bound)
        if plain or self._slow < 2:
            self._departure = 0.0
            return answer
        answers = np.array(self._answers).T
        residuals = answers - np.array(self._held).T
        weights = np.linalg.lstsq(np.diff(residuals, axis=1), answer - held, rcond=None)[0]
        mixed = np.clip(answer - np.diff(answers, axis=1) @ weights, -bound, bound)
        self._departure = _inf(mixed - answer)
        return np.asarray(mixed, dtype=np.float64)


def _forces(qp: StepQP, solution: StepSolution, friction: FloatArray) -> ContactForces:
    """The contact forces of ``solution`` of contact QP ``qp``, which held ``friction``."""
    count = len(qp.contacts)
    if qp.cones is None:  # every contact frictionless
        zero = np.zeros(count)
        rows = len(solution.ineq_dual) // max(count, 1) if count else 0
        normal = (0.5 * solution.ineq_dual.reshape(rows, count).sum(axis=0) if count
                  else zero)
        return ContactForces(zero, np.asarray(normal, dtype=np.float64), zero, zero)
    return ContactForces(qp.cones.coefficient, normal_impulses(qp, solution.ineq_dual),
                         friction, np.asarray(qp.cones.slip @ solution.x, dtype=np.float64))


@dataclass(frozen=True)
class ContactOutcome:
    """What the convergence test (:func:`_unchanged`) compares of two contact QPs."""

    motion: FloatArray
    """``sqrt(w) (x - t)`` per unknown (sqrt(J), whatever the unknown's units): the change
    of velocity that the contact QP's impulses (normal, friction and the constraints') give
    the bodies, ``t`` the step's own target (no friction impulse), each unknown counted by
    its kinetic energy.  Unique for a contact QP (its objective is strictly convex in
    ``x``), where the impulses are not."""
    twin_loads: FloatArray | None
    """Per contact, the normal impulse (N s) summed over its twin group
    (:func:`_twin_groups`): unique where the split among twins is not.  ``None`` once the
    contacts changed (the loads of other contacts are no measure of progress)."""

    @classmethod
    def of(cls, qp: StepQP, solution: StepSolution, target: FloatArray,
           twins: IntArray) -> ContactOutcome:
        """The outcome of ``solution`` of contact QP ``qp``; ``twins`` its :func:`_twin_groups`."""
        loads = np.bincount(twins, weights=normal_impulses(qp, solution.ineq_dual))
        return cls(np.asarray(np.sqrt(qp.weights) * (solution.x - target), dtype=np.float64),
                   np.asarray(loads[twins], dtype=np.float64))

    def without_loads(self) -> ContactOutcome:
        """The same outcome with its twin loads forgotten (the contacts changed)."""
        return dataclasses.replace(self, twin_loads=None)


TWIN_PARALLEL = 1e-6
"""``1 - cos`` (1) below which two contacts' normal rows count as parallel and the contacts
as twins: face-to-face cards' rows are parallel to round-off."""


def _twin_groups(qp: StepQP) -> IntArray:
    """A group label per contact of ``qp``, shared by twins (cards face to face).

    Twins: contacts with normal rows parallel to ``1 - cos < TWIN_PARALLEL`` (the connected
    components of that relation).  The split of a load among twins is not unique; its sum is.
    """
    assert qp.cones is not None
    rows = qp.cones.row_contact
    normal = sp.csr_array(qp.ineq_matrix[: len(rows)])
    per_row = np.diff(normal.indptr)
    squares = np.bincount(np.repeat(np.arange(len(rows)), per_row), weights=normal.data ** 2,
                          minlength=len(rows))
    norms = np.repeat(np.sqrt(np.where(squares > 0.0, squares, 1.0)), per_row)
    unit = sp.csr_array((normal.data / norms, normal.indices, normal.indptr), shape=normal.shape)
    cosines = sp.coo_array(unit @ unit.T)
    twin = (cosines.data > 1.0 - TWIN_PARALLEL) & (rows[cosines.row] != rows[cosines.col])
    count = len(qp.contacts)
    if not twin.any():
        return np.arange(count, dtype=np.int64)
    links = sp.coo_array((np.ones(int(twin.sum())),
                          (rows[cosines.row[twin]], rows[cosines.col[twin]])),
                         shape=(count, count))
    return np.asarray(connected_components(links, directed=False)[1], dtype=np.int64)


def _unchanged(now: ContactOutcome, previous: ContactOutcome, tolerance: float) -> bool:
    """Whether two contact QPs agree to ``tolerance`` (relative), in motion or in twin loads.

    Either suffices: the motion settles where the twins' split of a load drifts, and the
    twin loads' scale (the most loaded group's) does not shrink to one body's ``g dt`` on a
    resting step as the motion's does.
    """
    if _close(now.motion, previous.motion, tolerance):
        return True
    return (now.twin_loads is not None and previous.twin_loads is not None
            and _close(now.twin_loads, previous.twin_loads, tolerance))


def _close(now: FloatArray, previous: FloatArray, tolerance: float) -> bool:
    """Whether ``now`` and ``previous`` differ by at most ``tolerance`` times ``now``'s largest."""
    return now.shape == previous.shape and bool(_inf(now - previous) <= tolerance * _inf(now))


def _carried(values: FloatArray, old: Contacts, new: Contacts) -> FloatArray:
    """``values`` per contact of ``old`` moved to the same contacts of ``new`` (0 elsewhere)."""
    if old is new:
        return values
    return ContactIndex.of(old.ids()[:len(values)]).carry(values, new.ids())


def _inf(values: FloatArray) -> float:
    return float(np.max(np.abs(values))) if np.size(values) else 0.0


@dataclass
class FrictionMemory:
    """The friction impulses (N s) of the last step's contacts, by the contacts' ids.

    What ``coulomb_warm_start`` starts the next step's fixed point from.  An island QP
    numbers its bodies on its own (:meth:`~wuerfel_cvx.step.contacts.Contacts.restricted`);
    ``boxes`` (the island's boxes, ``None``: every box) maps them back
    (:meth:`~wuerfel_cvx.step.contacts.Contacts.ids`).
    """

    n_boxes: int
    """Boxes of the whole model."""
    contacts: ContactIndex = dataclasses.field(default_factory=ContactIndex.empty)
    """The last step's contacts, by their ids in the whole model's numbering."""
    impulses: FloatArray = dataclasses.field(default_factory=lambda: np.zeros(0))
    """The friction impulse (N s) of each of :attr:`contacts`."""

    def initial(self, contacts: Contacts, boxes: IntArray | None) -> FloatArray:
        """The remembered impulse of each of ``contacts`` (0 for a new contact)."""
        return self.contacts.carry(self.impulses, contacts.ids(boxes, self.n_boxes))

    def remember(self, steps: Sequence[tuple[CoulombStep, IntArray | None]]) -> None:
        """Keep the impulses the fixed points of one step ended with, forget the rest."""
        if not steps and not self.impulses.size:
            return  # nothing remembered, nothing to forget (every step without the fixed point)
        self.contacts = ContactIndex.of(np.concatenate(
            [np.zeros((0, 3), dtype=np.int64)]
            + [outcome.qp.contacts.ids(boxes, self.n_boxes) for outcome, boxes in steps]))
        self.impulses = np.concatenate(
            [np.zeros(0)] + [np.asarray(outcome.forces.friction, dtype=np.float64)
                             for outcome, _ in steps])


class CoulombNotConverged(RuntimeWarning):
    """A step's Coulomb fixed point reached its iteration limit (the step goes on)."""


COULOMB_COLUMNS = NULLABLE_COLUMNS
"""The fixed point's metrics columns and their (nullable) dtypes: friction problems solved
in the step (the most of any island QP) and whether every island's fixed point converged.
Empty (``NA``) in a run without the fixed point (``ccp``, no friction) and in a step that
solved no QP; ``0`` and true in a ``coulomb`` step without any contact with friction."""


def coulomb_settings(formulation: Formulation) -> CoulombSettings:
    """The fixed point's settings of ``formulation`` (its ``coulomb_*`` fields)."""
    fields: Any = formulation  # velocity and rigid have them; the protocol does not
    return CoulombSettings(int(fields.coulomb_max_iterations), float(fields.coulomb_tolerance))


def coulomb_columns(step: int, outcomes: Sequence[CoulombStep | None], active: bool, *,
                    warn: bool = True) -> dict[str, object]:
    """The :data:`COULOMB_COLUMNS` of a step whose island QPs gave ``outcomes``.

    ``active``: the run uses the fixed point.  A step whose fixed point did not converge
    is reported by a :class:`CoulombNotConverged` warning naming the step if ``warn`` (a
    run warns of its first such step; its metrics and summary name them all).
    """
    if not active:
        return dict.fromkeys(COULOMB_COLUMNS, pd.NA)
    ran = [outcome for outcome in outcomes if outcome is not None]
    iterations = max((outcome.iterations for outcome in ran), default=0)
    converged = all(outcome.converged for outcome in ran)
    if not converged and warn:
        warnings.warn(f"step {step}: the Coulomb fixed point did not converge in {iterations} "
                      "iterations; the step goes on with its last iterate (later such steps "
                      "are in the metrics' coulomb_converged and the run's summary)",
                      CoulombNotConverged, stacklevel=3)
    return {"coulomb_iterations": iterations, "coulomb_converged": converged}
