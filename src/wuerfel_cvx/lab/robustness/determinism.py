"""Fingerprints of trajectories, for determinism tests and the golden reference runs.

Two digests of a run's corner positions ``points`` ``(steps + 1, 4 n, 2)``:

:func:`exact_digest`
    sha256 of the raw float64 bytes (positions and velocities).  Two runs are
    bit-identical exactly when these agree; used within one machine (same process,
    a fresh process).

:func:`rounded_digest`
    sha256 of ``np.round(points, 9)``.  This is what the golden file
    ``tests/golden/trajectory_hashes.toml`` pins: a change of the model, the
    formulation, the step or the solver's answer by more than 1e-9 m changes it.
    1e-9 m is far above the round-off that differs between machines (a few ulps of
    positions of order 1 m, 1e-16 to 1e-15 m; a 1e-15 change of the start grows to
    3e-15 m over the 100 steps, as ``tests/test_determinism.py`` measures) and far
    below any physical change (solver tolerance 1e-7, penetrations of 1e-11 m and up).
    Limitation: rounding cannot make a digest robust to every tiny difference.  A value
    within ``delta`` of a rounding boundary (a multiple of 1e-9 plus 5e-10) flips when
    perturbed by ``delta``, so a round-off difference ``delta`` changes the digest of
    ``N`` numbers with probability about ``N delta / 1e-9`` (2e-3 for the 1616 positions
    of the golden run and ``delta = 1e-15``).  A golden mismatch therefore calls for a
    look at the size of the change (:func:`largest_difference` against a run saved
    before), not for a blind regeneration.

``python -m wuerfel_cvx.lab.robustness.determinism`` prints the golden file's content for
the installed versions; it never writes the file (regenerate deliberately, by hand).
"""

from __future__ import annotations

import hashlib
import sys
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass
from functools import cache

import numpy as np

from ...formulations import DEFAULT_FORMULATION, FORMULATIONS
from ...scenes.geometry import FloatArray
from ...simulate import simulate
from ...solve.registry import SOLVERS
from ...trajectory import Trajectory
from ...versions import package_version

#: Decimals (of metres) the golden digests round positions to.
GOLDEN_DECIMALS = 9

#: Solvers the golden file pins.
GOLDEN_SOLVERS = ("CLARABEL", "OSQP", "PIQP")

#: The solver of the golden file's per-formulation digests (one per formulation, so that a
#: change of what a formulation's name means, not only the default's, changes the
#: fingerprint).
FORMULATION_SOLVER = "CLARABEL"

#: Packages whose versions decide the golden digests (the solver's own is added).
PINNED_PACKAGES = ("numpy", "scipy", "cvxpy")

@dataclass(frozen=True)
class GoldenRun:
    """The reference run each golden digest is taken of."""

    scene: str = "two-corner-landing"
    """A library scene with contacts from its first steps: a square lands on another."""
    dt: float = 0.01
    """Time step (s)."""
    steps: int = 100
    """Number of steps."""
    tol: str = "default"
    """Solver tolerance preset."""
    friction_model: str = "ccp"
    """Friction model (the scenes without friction do not use it)."""

    def run(self, solver: str, formulation: str = DEFAULT_FORMULATION) -> Trajectory:
        """Simulate the reference run with ``solver`` (the default formulation unless given)."""
        return simulate(self.scene, dt=self.dt, steps=self.steps, solver=solver, tol=self.tol,
                        formulation=formulation, friction_model=self.friction_model)


GOLDEN_RUN = GoldenRun()

FORMULATION_RUN = GoldenRun(scene="tilted-drop")
"""The run of every formulation's digest: a spinning square that lands on a corner and
tips (the landing on a face of :data:`GOLDEN_RUN` does not tell a formulation's
linearisations apart: ``rigid`` and ``rigid-baumgarte`` agree on it to 1e-15 m, and differ
here by 2.6e-7 m)."""

FRICTION_MODELS = ("ccp", "coulomb")
"""The friction models the golden file pins, each by :func:`friction_digest`."""

FRICTION_SCENE = "friction-slide"
"""The scene of the friction models' digests: a square launched along a table with mu 0.5
slides, stops after 0.61 s and rests (the golden runs above have no friction, so without
these a change of a friction model would leave the fingerprint as it was)."""


def exact_digest(trajectory: Trajectory) -> str:
    """sha256 (hex) of the raw bytes of positions and velocities: equal iff bit-identical."""
    digest = hashlib.sha256()
    digest.update(np.ascontiguousarray(trajectory.points, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(trajectory.velocities, dtype=np.float64).tobytes())
    return digest.hexdigest()


def rounded_digest(points: FloatArray, decimals: int = GOLDEN_DECIMALS) -> str:
    """sha256 (hex) of the positions rounded to ``decimals`` (m); ``-0.0`` counts as ``0.0``."""
    rounded = np.round(np.asarray(points, dtype=np.float64), decimals) + 0.0
    return hashlib.sha256(np.ascontiguousarray(rounded).tobytes()).hexdigest()


def largest_difference(a: Trajectory, b: Trajectory) -> float:
    """Largest absolute difference (m) between the positions of two runs of equal length."""
    return float(np.max(np.abs(a.points - b.points)))


def pinned_versions(solver: str) -> dict[str, str]:
    """Installed versions of the packages a golden digest depends on."""
    packages = (*PINNED_PACKAGES, SOLVERS[solver].package)
    return {package: package_version(package) for package in packages}


def fingerprint_of(digests: Mapping[str, str]) -> str:
    """The physics fingerprint of a set of golden digests (name -> digest): 12 hex digits.

    The names are the solvers of the default formulation's runs, ``formulation:<name>``
    for :data:`FORMULATION_SOLVER`'s run of every formulation and ``friction:<model>`` for
    its run of every friction model (:func:`friction_digest`).

    Equal for two sets exactly when every digest is; a report states the fingerprint of the
    physics it was measured on (:func:`physics_fingerprint`), and a test compares it with
    the golden file's (:func:`golden_fingerprint`).
    """
    text = "\n".join(f"{solver} {digest}" for solver, digest in sorted(digests.items()))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:12]


@cache
def physics_fingerprint() -> str:
    """The fingerprint of this installation's physics: the golden runs, run now (about 2 s)."""
    return fingerprint_of({solver: rounded_digest(GOLDEN_RUN.run(solver).points)
                           for solver in GOLDEN_SOLVERS}
                          | {f"formulation:{name}": formulation_digest(name)
                             for name in FORMULATIONS}
                          | {f"friction:{model}": friction_digest(model)
                             for model in FRICTION_MODELS})


def formulation_digest(formulation: str) -> str:
    """The rounded digest of :data:`FORMULATION_SOLVER`'s golden run of ``formulation``."""
    return rounded_digest(FORMULATION_RUN.run(FORMULATION_SOLVER, formulation).points)


def friction_digest(model: str) -> str:
    """The rounded digest of a run of :data:`FRICTION_SCENE` with friction model ``model``.

    :data:`FORMULATION_SOLVER`, the default formulation, :data:`GOLDEN_RUN`'s settings.
    """
    run = GoldenRun(scene=FRICTION_SCENE, friction_model=model)
    return rounded_digest(run.run(FORMULATION_SOLVER).points)


def golden_fingerprint(text: str) -> str:
    """The fingerprint of a golden file's digests (its TOML ``text``)."""
    golden = tomllib.loads(text)
    return fingerprint_of(
        {solver: str(entry["sha256"]) for solver, entry in golden["solvers"].items()}
        | {f"formulation:{name}": str(entry["sha256"])
           for name, entry in golden.get("formulations", {}).items()}
        | {f"friction:{name}": str(entry["sha256"])
           for name, entry in golden.get("friction", {}).items()})


def golden_file_text() -> str:
    """The golden file's content (TOML) for the installed versions."""
    lines = [
        "# Golden digests of short reference runs (wuerfel_cvx.lab.robustness.determinism).",
        "# Each is sha256 of np.round(points, 9) over the run below; tests/test_determinism.py",
        "# compares them when the installed versions equal the ones recorded here.",
        "# Regenerate deliberately, after checking why the trajectories changed:",
        "#     python -m wuerfel_cvx.lab.robustness.determinism"
        " > tests/golden/trajectory_hashes.toml",
        "",
        "[run]",
        f'scene = "{GOLDEN_RUN.scene}"',
        f"dt = {GOLDEN_RUN.dt}",
        f"steps = {GOLDEN_RUN.steps}",
        f'tol = "{GOLDEN_RUN.tol}"',
        f"decimals = {GOLDEN_DECIMALS}",
    ]
    for solver in GOLDEN_SOLVERS:
        trajectory = GOLDEN_RUN.run(solver)
        lines += ["", f"[solvers.{solver}]", f'sha256 = "{rounded_digest(trajectory.points)}"']
        lines += [f'versions.{package} = "{value}"'
                  for package, value in pinned_versions(solver).items()]
    lines += ["", f"# Every formulation's run of {FORMULATION_RUN.scene} (the other settings "
              f"as above) with {FORMULATION_SOLVER}", "# (its versions above)."]
    for name in FORMULATIONS:
        lines += ["", f'[formulations."{name}"]', f'sha256 = "{formulation_digest(name)}"']
    lines += ["", f"# Each friction model's run of {FRICTION_SCENE} (the default formulation, "
              f"the other settings", f"# as above) with {FORMULATION_SOLVER} (its versions above)."]
    for model in FRICTION_MODELS:
        lines += ["", f'[friction."{model}"]', f'sha256 = "{friction_digest(model)}"']
    return "\n".join(lines) + "\n"


if __name__ == "__main__":  # pragma: no cover - a deliberate, manual regeneration aid
    sys.stdout.write(golden_file_text())
