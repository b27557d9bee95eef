"""Convergence-test candidates for the Coulomb fixed point (report section "Convergence-test
candidates").  Importing this module with CAND set replaces ``simulation.fixed_point`` by a
copy of the branch's ``fixed_point`` whose test is:

  V    the branch: max |sqrt(w) dx| <= tol * max |sqrt(w)(x - t)|   (net motion scale)
  E    V or main's per-contact normal-impulse test (max |dN| <= tol * max N)
  GDT  V with the scale max(max |sqrt(w)(x - t)|, sqrt(max w) g dt)
  GL   per unknown: |sqrt(w_i) dx_i| <= tol * max(gross_i, 1e-3 max_j gross_j)
  E2   E, but the mixer turns plain (holds the friction problem's answer) on V only
  EK   V, or main's test when V passes at K times the tolerance (env EK=K)
  OM   main's test on twin-merged contacts: normal impulses summed over groups of contacts
       whose normal rows are parallel to 1 - cos < 1e-6 (the split among them is not unique)
  OMV  OM or V
  G    V with the gross scale max_i (|G|'|z|/2 + |S|'|lambda_t| + |E|'|y|/2)_i / sqrt(w_i):
       every impulse on an unknown counted by its magnitude (does not cancel at rest);
       GFAC=f multiplies the gross scale by f
All keep the mixer's own check (FrictionMixer.settled) and the rest of fixed_point as on
the branch; the mixer turns plain when the candidate's test passes (E2: when V passes).
"""
import dataclasses
import os

import numpy as np

import wuerfel_cvx.friction.coulomb as C
import wuerfel_cvx.step.simulation as S
from wuerfel_cvx.friction.problem import friction_problem, normal_impulses, solve_friction

CAND = os.environ.get("CAND", "V")
G_ACC = 9.81


def _inf(v):
    return float(np.max(np.abs(v))) if np.size(v) else 0.0


def _measure(qp, sol, target, friction, dt):
    motion = np.sqrt(qp.weights) * (sol.x - target)
    scale = _inf(motion)
    if CAND == "GDT":
        scale = max(scale, float(np.sqrt(np.max(qp.weights))) * G_ACC * dt)
    elif CAND in ("G", "GL"):
        G = abs(qp.ineq_matrix)
        gross = G.T @ np.abs(sol.ineq_dual) / 2 + abs(qp.cones.slip).T @ np.abs(friction)
        if qp.eq_matrix.shape[0] and np.size(sol.eq_dual):
            gross = gross + abs(qp.eq_matrix).T @ np.abs(sol.eq_dual) / 2
        w = qp.weights
        gross = np.where(w > 0, gross / np.sqrt(np.where(w > 0, w, 1.0)), 0.0)
        gross = gross * float(os.environ.get("GFAC", "1"))  # G: the gross scale times GFAC
        scale = gross if CAND == "GL" else max(scale, _inf(gross))
    normal = normal_impulses(qp, sol.ineq_dual) if CAND in ("E", "E2", "EK", "OM", "OMV") else None
    if CAND in ("OM", "OMV"):
        normal = np.bincount(_twins(qp), weights=normal)
    return motion, scale, normal


def _twins(qp):
    """Group label per contact: contacts joined when two of their normal rows are parallel."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    rows = qp.cones.row_contact
    G = sp.csr_array(qp.ineq_matrix[: len(rows)])
    norms = np.sqrt(np.asarray(G.multiply(G).sum(axis=1)).ravel())
    R = sp.diags(1 / np.where(norms > 0, norms, 1.0)) @ G
    P = sp.coo_array(R @ R.T)
    keep = (P.data > 1 - 1e-6) & (rows[P.row] != rows[P.col])
    n = len(qp.contacts)
    A = sp.coo_array((np.ones(int(keep.sum())), (rows[P.row[keep]], rows[P.col[keep]])),
                     shape=(n, n))
    return connected_components(A, directed=False)[1]


def _settled(now, prev, tol, plain_only=False):
    if prev is None:
        return False
    motion, scale, normal = now
    pmotion, _, pnormal = prev
    if CAND == "GL":
        ok = motion.shape == pmotion.shape and bool(np.all(
            np.abs(motion - pmotion) <= tol * np.maximum(scale, 1e-3 * _inf(scale))))
    else:
        ok = motion.shape == pmotion.shape and _inf(motion - pmotion) <= tol * scale
    if plain_only:
        return bool(ok)
    if CAND == "EK" and not ok and pnormal is not None and normal.shape == pnormal.shape:
        ok = _inf(motion - pmotion) <= float(os.environ["EK"]) * tol * scale \
            and _inf(normal - pnormal) <= tol * _inf(normal)
    if CAND == "OM":
        return bool(pnormal is not None and normal.shape == pnormal.shape
                    and _inf(normal - pnormal) <= tol * _inf(normal))
    if CAND in ("E", "E2", "OMV") and not ok and pnormal is not None and normal.shape == pnormal.shape:
        ok = _inf(normal - pnormal) <= tol * _inf(normal)
    return bool(ok)


def fixed_point(formulation, model, state, qp, dt, solve, tol, settings, initial=None):
    target = qp.target
    base = qp
    friction = np.zeros(len(qp.contacts)) if initial is None else np.asarray(initial, float)
    solved, answers = [], []
    previous = None
    mixer = C.FrictionMixer(settings.memory)
    linearisations, converged = 1, False
    while True:
        contact_qp = C.with_friction_impulse(base, friction)
        solved.append(solve(contact_qp, repeated=True))
        solution = solved[-1][0]
        refined = formulation.refine(model, state, contact_qp, solution.x, dt, linearisations)
        if contact_qp.cones is None:
            if refined is None:
                converged = True
                break
            linearisations += 1
            base, friction = dataclasses.replace(refined, target=target), \
                np.zeros(len(refined.contacts))
            mixer.reset()
            continue
        now = _measure(contact_qp, solution, target, friction, dt)
        test = _settled(now, previous, settings.tolerance)
        settled = test and mixer.settled(settings.tolerance)
        if refined is None and (settled or len(answers) >= settings.max_iterations):
            converged = settled
            break
        new_impulse = not settled and len(answers) < settings.max_iterations
        if new_impulse:
            problem = friction_problem(contact_qp, solution, target)
            answers.append(solve_friction(problem, solve, tol))
            plain = _settled(now, previous, settings.tolerance, True) if CAND == "E2" else test
            friction = mixer.next(friction, answers[-1].friction, problem.bound, plain=plain)
            previous = now
        linearisations = 1 if new_impulse else linearisations + 1
        if refined is not None:
            base = dataclasses.replace(refined, target=target)
            if base.contacts is not contact_qp.contacts:
                mixer.reset()
            friction = C._carried(friction, contact_qp.contacts, base.contacts)
            if previous is not None and previous[2] is not None and CAND in ("OM", "OMV") \
                    and base.contacts is not contact_qp.contacts:
                previous = (previous[0], previous[1], None)
            elif previous is not None and previous[2] is not None and CAND not in ("OM", "OMV"):
                previous = (previous[0], previous[1],
                            C._carried(previous[2], contact_qp.contacts, base.contacts))
    return C.CoulombStep(contact_qp, solved, answers, converged,
                         C._forces(contact_qp, solution, friction))


if os.environ.get("CAND"):
    S.fixed_point = fixed_point
