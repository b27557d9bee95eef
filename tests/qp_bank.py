"""A bank of step QPs from library scenes, and the agreement bound of their solutions.

:data:`AGREEMENT` bounds how far two verified solutions of one of these QPs may differ.

Each entry is built from a state of a reference run (CLARABEL, tight tolerance) at a
step where contacts are active, so the bank holds impacts, resting contacts,
redundant (aligned-stack) contacts, deep overlap and a large mass ratio.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.formulations import StepQP, get_formulation, step_qp
from wuerfel_cvx.solve.paths import VERIFY_FACTOR
from wuerfel_cvx.solve.registry import TOLERANCE_PRESETS
from wuerfel_cvx.step.model import Model, State

DT = 0.01

# Both solutions pass the residual check at VERIFY_FACTOR * eps (relative).  The QP is
# strongly convex with Hessian 2 W, W >= m/4 = 0.25 kg per coordinate for the bank's
# squares, and its right-hand sides and targets are below 5 m/s, so a residual r moves
# the minimiser by at most about r (1 + 5 m/s) / (2 * 0.25 kg) = 12 r; two solutions
# may differ by twice that.
AGREEMENT = 2 * 12 * VERIFY_FACTOR * TOLERANCE_PRESETS["high"]  # m/s (2.4e-6)

#: (scene, formulation, steps to run before taking the QP)
BANK_CASES: tuple[tuple[str, str, int], ...] = (
    ("tilted-drop", "velocity", 55),
    ("tilted-drop", "velocity", 70),
    ("corner-drop", "velocity", 56),
    ("stack-3", "velocity", 0),
    ("pyramid-3", "velocity", 5),
    ("rain-8", "velocity", 120),
    ("overlap-recovery", "velocity", 0),
    ("heavy-on-light", "velocity", 3),
    ("fast-drop", "velocity", 5),
    ("single-drop", "seed", 56),
    ("stack-3", "seed", 1),
)


@dataclass(frozen=True)
class BankEntry:
    """One step QP of the bank and where it came from."""

    label: str
    formulation: str
    model: Model
    state: State

    def build(self) -> StepQP:
        """A fresh cvxpy problem for this step (each solve gets its own)."""
        return step_qp(get_formulation(self.formulation), self.model, self.state, DT)


@cache
def qp_bank() -> tuple[BankEntry, ...]:
    """The bank, built once per test session."""
    entries = []
    for scene_name, formulation, steps in BANK_CASES:
        scene = Scene.named(scene_name)
        run = simulate(scene, dt=DT, steps=steps, formulation=formulation, tol="high")
        state = State(run.points[-1], run.velocities[-1])
        entries.append(BankEntry(f"{scene_name}/{formulation}@{steps}", formulation,
                                 Model.from_scene(scene), state))
    return tuple(entries)
