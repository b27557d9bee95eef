"""Instrumented Coulomb fixed point on the card house: per iteration quantities."""
from __future__ import annotations
import dataclasses, sys, json, pickle
import numpy as np
import wuerfel_cvx.friction.coulomb as C
import wuerfel_cvx.step.simulation as S
from wuerfel_cvx.friction.problem import friction_problem, normal_impulses, solve_friction

LOG: list = []

def fixed_point(formulation, model, state, qp, dt, solve, tol, settings, initial=None):
    target = qp.target; base = qp
    friction = np.zeros(len(qp.contacts)) if initial is None else np.asarray(initial, float)
    solved, answers = [], []
    previous = None
    mixer = C.FrictionMixer(settings.memory)
    linearisations, converged = 1, False
    rec = []
    LOG.append(rec)
    while True:
        contact_qp = C.with_friction_impulse(base, friction)
        solved.append(solve(contact_qp, repeated=True))
        solution = solved[-1][0]
        refined = formulation.refine(model, state, contact_qp, solution.x, dt, linearisations)
        if contact_qp.cones is None:
            if refined is None:
                converged = True; break
            linearisations += 1
            base, friction = dataclasses.replace(refined, target=target), np.zeros(len(refined.contacts))
            mixer.reset(); continue
        normal = normal_impulses(contact_qp, solution.ineq_dual)
        nrows = len(contact_qp.cones.row_contact)
        rec.append(dict(x=solution.x.copy(), rows=solution.ineq_dual[:nrows].copy(),
                        row_contact=contact_qp.cones.row_contact.copy(), normal=normal.copy(),
                        held=friction.copy(), refined=refined is not None, w=contact_qp.weights.copy(),
                        ids=contact_qp.contacts.ids().copy(), G=contact_qp.ineq_matrix[:nrows].toarray(),
                        slip=contact_qp.cones.slip @ solution.x, path=solution.path, t=target.copy(), S=contact_qp.cones.slip.toarray() if hasattr(contact_qp.cones.slip, 'toarray') else np.asarray(contact_qp.cones.slip), mu=contact_qp.cones.coefficient.copy()))
        settled = previous is not None and C._settled(normal, previous, settings) and mixer.settled(settings.tolerance)
        if refined is None and (settled or len(answers) >= settings.max_iterations):
            converged = settled; break
        new_impulse = not settled and len(answers) < settings.max_iterations
        if new_impulse:
            problem = friction_problem(contact_qp, solution, target)
            answers.append(solve_friction(problem, solve, tol))
            plain = previous is not None and C._settled(normal, previous, settings)
            friction = mixer.next(friction, answers[-1].friction, problem.bound, plain=plain)
            rec[-1].update(answer=answers[-1].friction.copy(), bound=problem.bound.copy(),
                           next=friction.copy(), departure=mixer._departure, radius=mixer._radius,
                           plain=plain, ax=answers[-1].x.copy())
            previous = normal
        linearisations = 1 if new_impulse else linearisations + 1
        if refined is not None:
            base = dataclasses.replace(refined, target=target)
            if base.contacts is not contact_qp.contacts:
                mixer.reset()
            friction = C._carried(friction, contact_qp.contacts, base.contacts)
            previous = None if previous is None else C._carried(previous, contact_qp.contacts, base.contacts)
    return C.CoulombStep(contact_qp, solved, answers, converged, C._forces(contact_qp, solution, friction))

if __name__ == "__main__":
    from wuerfel_cvx import simulate
    solver, steps, out = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    S.fixed_point = fixed_point
    import os
    if os.environ.get("MAXIT") or os.environ.get("MEM"):
        orig = S.coulomb_settings
        def cs(f):
            st = orig(f)
            return C.CoulombSettings(int(os.environ.get("MAXIT", st.max_iterations)), st.tolerance,
                                     int(os.environ.get("MEM", st.memory)))
        S.coulomb_settings = cs
    import warnings; warnings.simplefilter("ignore")
    t = simulate("card-house", dt=1/60, steps=steps, solver=solver, friction_model="coulomb")
    m = t.metrics
    print(m[["coulomb_iterations", "coulomb_converged"]].to_string())
    with open(out, "wb") as f:
        pickle.dump(LOG, f)
