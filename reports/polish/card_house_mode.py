"""The card house's growing mode (``ccp``, ``rigid``, dt 1/60 s): which body, contact and term.

OSQP's run of ``card-house`` grows a mode from state 295 on (``card-house.md``).  This
script takes OSQP's states ``FIRST..LAST`` and

1. ``mode``: the growth factor of the body velocities per step and the mode's shape (the
   bodies that move, their ``(u_x, u_y, omega)`` relative to the largest);
2. ``contacts``: one CLARABEL step from each state; the contacts of the moving body that
   slide (one cone edge tight and loaded, the other slack), their gap ``g`` (m), slip ``s``
   and normal velocity ``n.v`` (m/s) after the step, the rows' right-hand side ``h``, the
   loaded edge's multiplier, ``t = n.v / s`` and the factor ``mu / (mu - t)`` that the
   ``ccp`` lift-off predicts for the gap (the markdown report derives it), against the gap
   measured in the next state;
3. ``jacobian``: the one-step map (CLARABEL) differentiated by one-sided finite differences
   at a state of the growing trajectory, in each body's centre, angle, centre velocity and
   spin (the moving body's six, or every body's); its largest eigenvalues and the
   eigenvector's body;
4. ``models``: from the same state, a few steps with ``ccp`` at dt 1/60 and 1/120 s and
   with ``coulomb`` at 1/60 s (CLARABEL): the largest body speed per step;
5. ``kicks``: card 22 turned about its foot at rest (state 285 of OSQP's and of CLARABEL's
   run), opening or closing its top's gap, then CLARABEL's steps: the gap and speed (also
   with the ``velocity`` formulation);
6. ``scan``: every body turned by +-5e-10 rad about its lowest corner at rest: which grow,
   and the sliding contact of the body that moves fastest;
7. ``coulomb``: ``coulomb``'s own run to its step 240, and card 22 turned there.

Run from the repository root (about a minute in all on a loaded 2-core machine; the
Jacobian of every body, ``--all-bodies``, takes longer)::

    PYTHONPATH=src python reports/polish/card_house_mode.py [PART ...] [--all-bodies]
        [--states PATH.npz]

``--states``: OSQP's states are read from there, or computed and saved there.
"""

from __future__ import annotations

import argparse
import copy
import os
import warnings

import numpy as np

from wuerfel_cvx import Scene
from wuerfel_cvx.formulations import StepQP
from wuerfel_cvx.formulations.cone import ConeRows
from wuerfel_cvx.formulations.rigid import body_velocities
from wuerfel_cvx.solve.paths import StepSolution
from wuerfel_cvx.step.contacts import Contacts
from wuerfel_cvx.step.model import State
from wuerfel_cvx.step.simulation import Simulation

FIRST, LAST = 285, 320
"""OSQP's states kept (step numbers; the growth runs from about 295 to 319)."""
AT = 310
"""The state the Jacobian and the other models start from (on the growing trajectory)."""
TIGHT = 1e-12
"""A row is tight when its slack is below this (m/s; the rows' right-hand sides are
1e-7 to 0.3 m/s here, the polished answers' residuals 1e-15)."""


def simulation(solver: str = "CLARABEL", dt: float = 1 / 60, friction_model: str = "ccp",
               formulation: str = "rigid") -> Simulation:
    """A card house simulation (``rigid``, the default formulation, unless told)."""
    return Simulation(Scene.named("card-house"), dt=dt, solver=solver,
                      friction_model=friction_model, formulation=formulation)


def restart(sim: Simulation, state: State) -> None:
    """Put ``sim`` at ``state`` with its contacts searched (as a run reaching it would)."""
    sim.state = state
    sim.contacts, _ = sim._search(state)


def osqp_states(path: str | None) -> dict[int, State]:
    """OSQP's states ``FIRST..LAST`` (from ``path`` if it exists, else run and saved there)."""
    if path is not None and os.path.exists(path):
        saved = np.load(path)
        return {k: State(saved[f"p{k}"], saved[f"v{k}"]) for k in range(FIRST, LAST + 1)}
    sim = simulation("OSQP")
    states = {}
    for k in range(1, LAST + 1):
        sim.step()
        if k >= FIRST:
            states[k] = sim.state
    if path is not None:
        arrays = {f"p{k}": s.points for k, s in states.items()}
        arrays.update({f"v{k}": s.velocities for k, s in states.items()})
        np.savez(path, allow_pickle=False, **arrays)
    return states


def body_coordinates(sim: Simulation, points: np.ndarray, deltas: np.ndarray) -> np.ndarray:
    """``(n, 3)``: the rigid motion ``(x, y, angle)`` nearest corner deltas ``(4 n, 2)``."""
    centre, spin = body_velocities(points, deltas, sim.model.point_masses.reshape(-1, 4))
    return np.concatenate([centre, spin[:, None]], axis=1)


def mode(sim: Simulation, states: dict[int, State]) -> int:
    """Print the growth per step and the mode's shape; return the body that moves most."""
    previous = None
    for k in range(FIRST, LAST + 1):
        now = body_coordinates(sim, states[k].points, states[k].velocities).ravel()
        if previous is not None and k >= 296:
            size, before = np.linalg.norm(now), np.linalg.norm(previous)
            print(f"step {k}: |body velocities| {size:.3e} m/s, x{size / before:.3f}, "
                  f"cosine with the step before {now @ previous / size / before:+.7f}")
        previous = now
    shape = body_coordinates(sim, states[AT].points, states[AT].velocities)
    shape /= np.abs(shape).max()
    moving = np.flatnonzero(np.abs(shape).max(axis=1) > 1e-3)
    for body in moving:
        box = sim.model.reference_corners[body]
        print(f"mode at state {AT}: body {body} (u_x, u_y, omega) {np.round(shape[body], 4)}, "
              f"size {np.ptp(box, axis=0)}")
    return int(np.abs(shape).max(axis=1).argmax())


def cones_of(qp: StepQP) -> ConeRows:
    """The QP's friction cones (every QP here has them: the card house has friction)."""
    assert qp.cones is not None
    return qp.cones


def sliding(qp: StepQP, solution: StepSolution) -> list[tuple[int, int]]:
    """``(normal row, loaded edge row)`` of each contact with exactly one edge tight and loaded."""
    cones, slack = cones_of(qp), qp.ineq_matrix @ solution.x - qp.ineq_rhs
    found = []
    for row, minus in enumerate(cones.minus):
        if minus < 0:
            continue
        tight = (slack[row] < TIGHT and solution.ineq_dual[row] > 0,
                 slack[minus] < TIGHT and solution.ineq_dual[minus] > 0)
        if tight[0] != tight[1]:
            found.append((row, row if tight[0] else int(minus)))
    return found


def lift_off_factor(state: State, foot: int = 88, top: int = 90, edge: tuple[int, int] = (80, 83),
                    mu: float = 0.7) -> None:
    """Print ``t`` and ``mu / (mu - t)`` from the geometry alone.

    ``t``: the top corner's normal over its tangential velocity, relative to the face
    ``edge`` (flat card 20's lower face), when the card turns about its foot corner.
    """
    p = state.points
    tangent = (p[edge[1]] - p[edge[0]]) / np.linalg.norm(p[edge[1]] - p[edge[0]])
    normal = np.array([tangent[1], -tangent[0]])
    arm = p[top] - p[foot]
    velocity = np.array([-arm[1], arm[0]])  # turning at 1 rad/s about the foot
    t = abs(normal @ velocity) / abs(tangent @ velocity)
    print(f"geometry: corner {top} turning about corner {foot}: t {t:.5f}, mu/(mu-t) "
          f"{mu / (mu - t):.5f} (the card leans {np.degrees(np.arctan2(-arm[0], arm[1])):.3f} "
          "deg from the vertical)")


def contacts(sim: Simulation, states: dict[int, State], body: int) -> None:
    """Print ``body``'s sliding contacts after one CLARABEL step from each state."""
    lift_off_factor(states[AT])
    for k in range(296, LAST):
        restart(sim, states[k])
        record = sim.step()
        qp, solution = record.qps[0], record.solutions[0]
        c, cones = qp.contacts, cones_of(qp)
        values = qp.ineq_matrix @ solution.x
        slip = cones.slip @ solution.x
        after = sim.contacts
        for row, loaded in sliding(qp, solution):
            j = int(cones.row_contact[row])
            if body not in (c.point_body[j], c.edge_body[j]) or row >= len(c) \
                    or abs(slip[j]) < 1e-12:
                continue  # the rate row only (the closest-approach row is the same
                # here), and no contact whose slip is round-off
            minus = int(cones.minus[row])
            normal = 0.5 * (values[row] + values[minus])
            mu, s = cones.coefficient[j], slip[j]
            t = normal / s
            same = np.flatnonzero((after.point == c.point[j]) & (after.edge_i == c.edge_i[j])
                                  & (after.edge_j == c.edge_j[j]))
            gap_after = after.distance[same[0]] if same.size else np.nan
            print(f"step {k}->{k + 1}: contact {j} (corner {c.point[j]} of body "
                  f"{c.point_body[j]} on body {c.edge_body[j]}), mu {mu:.2f}: gap "
                  f"{c.distance[j]:.3e} m, h {qp.ineq_rhs[row]:+.3e}, edge "
                  f"{'+' if loaded == row else '-'} loaded z {solution.ineq_dual[loaded]:.3e}, "
                  f"s {s:+.3e}, n.v {normal:+.3e}, mu|s| {mu * abs(s):.3e} m/s; "
                  f"t {t:.4f}, mu/(mu-t) {mu / (mu - abs(t)):.4f}; gap after {gap_after:.3e} m "
                  f"(x{gap_after / c.distance[j]:.4f}), "
                  f"g + dt n.v {c.distance[j] + sim.dt * normal:.3e}, "
                  f"dt mu|s| {sim.dt * mu * abs(s):.3e}")


def one_step(sim: Simulation, state: State) -> tuple[np.ndarray, np.ndarray]:
    """Points and velocities after one step from ``state``."""
    restart(sim, state)
    sim.step()
    return sim.state.points, sim.state.velocities


def perturbed(sim: Simulation, state: State, body: int, coordinate: int, eps: float) -> State:
    """``state`` with ``body``'s centre, angle (0-2) or velocity, spin (3-5) moved by ``eps``."""
    corners = slice(4 * body, 4 * body + 4)
    offsets = state.points[corners] - state.points[corners].mean(axis=0)
    delta = np.zeros((4, 2))
    if coordinate % 3 < 2:
        delta[:, coordinate % 3] = eps
    else:
        delta = eps * np.stack([-offsets[:, 1], offsets[:, 0]], axis=1)
    points, velocities = state.points.copy(), state.velocities.copy()
    (points if coordinate < 3 else velocities)[corners] += delta
    return State(points, velocities)


def jacobian(sim: Simulation, state: State, bodies: list[int], eps: float) -> np.ndarray:
    """One-sided differences of the one-step map in ``bodies``' 6 coordinates each."""
    base_points, base_velocities = one_step(sim, state)
    columns = []
    for body in bodies:
        for coordinate in range(6):
            points, velocities = one_step(sim, perturbed(sim, state, body, coordinate, eps))
            position = body_coordinates(sim, base_points, points - base_points)[bodies]
            velocity = body_coordinates(sim, base_points, velocities - base_velocities)[bodies]
            columns.append(np.concatenate([position, velocity], axis=1).ravel() / eps)
    # rows ordered as the columns: body by body, (x, y, angle, u_x, u_y, omega) each
    return np.array(columns).T


def eigen(sim: Simulation, states: dict[int, State], bodies: list[int]) -> None:
    """Print the largest eigenvalues of the map's Jacobian at state ``AT``, both signs."""
    for eps in (1e-11, -1e-11):
        matrix = jacobian(sim, states[AT], bodies, eps)
        values, vectors = np.linalg.eig(matrix)
        order = np.argsort(-np.abs(values))
        print(f"Jacobian at state {AT} ({len(bodies)} bodies, eps {eps:+.0e}): "
              "largest |eigenvalues|",
              np.round(values[order[:4]], 4))
        top = np.abs(vectors[:, order[0]]).reshape(len(bodies), 6)
        print("  its eigenvector's body:", bodies[int(top.max(axis=1).argmax())],
              "components (x, y, angle, u_x, u_y, omega) relative to the largest:",
              np.round(top[int(top.max(axis=1).argmax())] / top.max(), 4))


def models(states: dict[int, State]) -> None:
    """Print the largest body speed over a few steps from state ``AT`` under other settings."""
    for dt, friction_model in ((1 / 60, "ccp"), (1 / 120, "ccp"), (1 / 60, "coulomb")):
        sim = simulation(dt=dt, friction_model=friction_model)
        restart(sim, states[AT])
        speeds = []
        for _ in range(8):
            sim.step()
            speeds.append(np.abs(sim.state.velocities).max())
        print(f"{friction_model}, dt 1/{round(1 / dt)} s, from state {AT} "
              f"(in {np.abs(states[AT].velocities).max():.2e} m/s):",
              " ".join(f"{v:.2e}" for v in speeds))


def turned(state: State, body: int, pivot: int, angle: float) -> State:
    """``state`` with ``body`` turned by ``angle`` (rad, counter-clockwise) about ``pivot``.

    ``pivot``: the corner (row of ``points``) that stays put.
    """
    corners = slice(4 * body, 4 * body + 4)
    cos, sin = np.cos(angle), np.sin(angle)
    points = state.points.copy()
    offsets = points[corners] - points[pivot]
    points[corners] = points[pivot] + offsets @ np.array([[cos, sin], [-sin, cos]])
    return State(points, state.velocities.copy())


def gap_of(contacts: Contacts, point: int, body: int) -> float:
    """The gap (m) of corner ``point`` against ``body``'s face (NaN: no such contact)."""
    found = np.flatnonzero((contacts.point == point) & (contacts.edge_body == body))
    return float(contacts.distance[found[0]]) if found.size else float("nan")


KICKS = (5e-10, -5e-10, 5e-12, -5e-12, 0.0)
"""Turns (rad, counter-clockwise) of card 22 about its foot: 5e-10 rad opens its top's gap
by 8.4e-11 m, 5e-12 rad by 8.4e-13 m; clockwise turns close it by as much."""


def kicks(states: dict[int, State]) -> None:
    """Turn the card about its foot at rest (OSQP's and CLARABEL's states 285), CLARABEL on.

    The mode's card (22) stands on corner 88 and touches flat card 20 with corner 90; a
    counter-clockwise turn opens that gap, a clockwise one closes it.
    """
    sim = simulation()
    rest = {"OSQP": states[FIRST]}
    for _ in range(FIRST):
        sim.step()
    rest["CLARABEL"] = sim.state
    runs: list[tuple[str, State, Simulation, tuple[float, ...]]] = [
        (name, state, sim, KICKS) for name, state in rest.items()]
    runs.append(("OSQP", states[FIRST],
                 simulation(formulation="velocity"), (KICKS[0], 0.0)))
    for name, state, sim, angles in runs:
        for angle in angles:
            restart(sim, turned(state, 22, 88, angle))
            line = [f"gap {gap_of(sim.contacts, 90, 20):+.1e}"]
            for k in range(12):
                sim.step()
                if k % 3 == 2:
                    line.append(f"{k + 1}: gap {gap_of(sim.contacts, 90, 20):+.1e} m, "
                                f"speed {np.abs(sim.state.velocities).max():.1e} m/s")
            print(f"{name}'s state {FIRST}, {sim.formulation.name}, card 22 turned by "
                  f"{angle:+.0e} rad:", "; ".join(line))


def scan(states: dict[int, State]) -> None:
    """Each card turned by +-5e-10 rad about its lowest corner at rest (CLARABEL's steps).

    Prints the speed's factor per step over steps 3 to 6, and for a turn that grows, the
    fastest body's sliding contact in the sixth step (:func:`sliding`, the largest slip):
    its corner, the face's body, ``t = n.v / s`` and ``mu / (mu - t)``.
    """
    sim = simulation()
    rest = states[FIRST]
    for body in range(sim.model.n_boxes):
        corners = rest.points[4 * body: 4 * body + 4]
        foot = 4 * body + int(corners[:, 1].argmin())
        factors, notes = [], []
        for angle in (5e-10, -5e-10):
            restart(sim, turned(rest, body, foot, angle))
            speeds = []
            for _ in range(6):
                record = sim.step()
                speeds.append(np.abs(sim.state.velocities).max())
            factors.append((speeds[5] / speeds[2]) ** (1 / 3))
            if factors[-1] > 1.5:
                notes.append(f"{'counter-clockwise' if angle > 0 else 'clockwise'}: "
                             + slider(sim, record.qps[0], record.solutions[0]))
        print(f"body {body:2d} (foot corner {foot:3d}): factor per step, turned "
              f"counter-clockwise {factors[0]:.3f}, clockwise {factors[1]:.3f}"
              + "".join(f"; {note}" for note in notes))


def slider(sim: Simulation, qp: StepQP, solution: StepSolution) -> str:
    """The fastest body's sliding contact of largest slip in ``solution``, described."""
    fastest = int(np.abs(body_coordinates(sim, sim.state.points, sim.state.velocities))
                  .max(axis=1).argmax())
    c, cones = qp.contacts, cones_of(qp)
    values, slip = qp.ineq_matrix @ solution.x, cones.slip @ solution.x
    best, text = 0.0, f"fastest body {fastest}, no sliding contact"
    for row, _ in sliding(qp, solution):
        j = int(cones.row_contact[row])
        if fastest in (c.point_body[j], c.edge_body[j]) and abs(slip[j]) > best:
            best, mu = abs(slip[j]), cones.coefficient[j]
            t = 0.5 * (values[row] + values[cones.minus[row]]) / abs(slip[j])
            text = (f"fastest body {fastest}, sliding corner {c.point[j]} (body "
                    f"{c.point_body[j]}) on body {c.edge_body[j]}: t {t:.4f}, "
                    f"mu/(mu-t) {mu / (mu - t):.4f}")
    return text


def coulomb(steps: int = 240) -> None:
    """``coulomb``'s own run to ``steps``, then card 22 turned there as in :func:`kicks`.

    Each turned run continues from a copy of the run's friction memory (the last step's
    impulses, which start the fixed point).
    """
    sim = simulation(friction_model="coulomb")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its unconverged steps are counted below
        for _ in range(steps):
            sim.step()
        converged = sum(bool(row["coulomb_converged"]) for row in sim.recorder.rows)
        print(f"coulomb, {steps} steps from the start: fixed point converged in {converged}; "
              f"largest speed {np.abs(sim.state.velocities).max():.1e} m/s")
        for angle in KICKS[:2] + (0.0,):
            other = simulation(friction_model="coulomb")
            other._friction_memory = copy.deepcopy(sim._friction_memory)
            restart(other, turned(sim.state, 22, 88, angle))
            line = [f"gap {gap_of(other.contacts, 90, 20):+.1e}"]
            for k in range(6):
                other.step()
                line.append(f"{k + 1}: {gap_of(other.contacts, 90, 20):+.1e} m, "
                            f"{np.abs(other.state.velocities).max():.0e} m/s")
            print(f"coulomb's state {steps}, card 22 turned by {angle:+.0e} rad:", "; ".join(line))


def main() -> None:
    """Run the parts named on the command line (all by default)."""
    parser = argparse.ArgumentParser()
    parser.add_argument("parts", nargs="*",
                        default=["mode", "contacts", "jacobian", "models", "kicks", "scan",
                                 "coulomb"])
    parser.add_argument("--states", default=None)
    parser.add_argument("--all-bodies", action="store_true")
    args = parser.parse_args()
    states = osqp_states(args.states)
    sim = simulation()
    body = mode(sim, states) if "mode" in args.parts else 22
    if "contacts" in args.parts:
        contacts(sim, states, body)
    if "jacobian" in args.parts:
        eigen(sim, states, list(range(sim.model.n_boxes)) if args.all_bodies else [body])
    if "models" in args.parts:
        models(states)
    if "kicks" in args.parts:
        kicks(states)
    if "scan" in args.parts:
        scan(states)
    if "coulomb" in args.parts:
        coulomb()


if __name__ == "__main__":
    main()
