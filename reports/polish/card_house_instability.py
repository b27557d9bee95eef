"""The card house's growing mode: one step from each of OSQP's states 300-311, by both solvers.

The card house (``ccp``, ``rigid``, dt 1/60 s) run with OSQP; from each state, one more
step is taken by that run and by a fresh CLARABEL simulation started from the same state.
Prints the largest corner speed (m/s) going in, each solver's speed coming out, and their
largest difference (``reports/polish/card-house.md``).  Run from the repository root::

    PYTHONPATH=src python reports/polish/card_house_instability.py
"""

import numpy as np

from wuerfel_cvx import Scene
from wuerfel_cvx.step.simulation import Simulation

FIRST, STEPS = 300, 12


def fresh(solver: str) -> Simulation:
    """A new simulation of the card house with ``solver``."""
    return Simulation(Scene.named("card-house"), dt=1 / 60, solver=solver,
                      friction_model="ccp")


def main() -> None:
    run = fresh("OSQP")
    for _ in range(FIRST):
        run.step()
    for k in range(STEPS):
        state = run.state
        other = fresh("CLARABEL")
        other.state = state
        other.contacts, _ = other._search(state)
        other.step()
        run.step()
        print(FIRST + k, f"in {np.abs(state.velocities).max():.2e}",
              f"OSQP {np.abs(run.state.velocities).max():.2e}",
              f"CLARABEL {np.abs(other.state.velocities).max():.2e}",
              f"difference {np.abs(run.state.velocities - other.state.velocities).max():.2e}")


if __name__ == "__main__":
    main()
