"""Determinism: the same scene, solver and settings give the same bits, here and anywhere.

Each solver's reference run (:data:`GOLDEN_RUN`: a square landing on another, contacts in
every step) is run twice in this process and once in a fresh interpreter, and must be
bit-identical each time.  Its positions rounded to 1e-9 m must match the digest pinned in
``tests/golden/trajectory_hashes.toml`` when the installed versions are those recorded
there.  To regenerate that file deliberately (never automatically), print it with
``python -m wuerfel_cvx.lab.robustness.determinism`` and check why the trajectory changed.
"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
import tomllib
from functools import cache
from pathlib import Path

import pytest

from wuerfel_cvx import Scene, simulate
from wuerfel_cvx.formulations import FORMULATIONS
from wuerfel_cvx.lab.robustness.determinism import (
    FORMULATION_RUN,
    FORMULATION_SOLVER,
    FRICTION_MODELS,
    FRICTION_SCENE,
    GOLDEN_DECIMALS,
    GOLDEN_RUN,
    GOLDEN_SOLVERS,
    exact_digest,
    fingerprint_of,
    formulation_digest,
    friction_digest,
    golden_fingerprint,
    largest_difference,
    physics_fingerprint,
    pinned_versions,
    rounded_digest,
)
from wuerfel_cvx.trajectory import Trajectory

pytestmark = pytest.mark.integration

GOLDEN_FILE = Path(__file__).parent / "golden" / "trajectory_hashes.toml"

#: A relative perturbation of the initial state the size of a few ulps (2.2e-16 each):
#: the kind of difference another CPU, compiler or BLAS could make in one operation.
ROUND_OFF_PERTURBATION = 1e-15


def perturbed_start(scene: Scene) -> Scene:
    """``scene`` with every square's angle (rad) and height (m) moved by the round-off size."""
    return dataclasses.replace(scene, squares=tuple(
        dataclasses.replace(square, angle=square.angle + ROUND_OFF_PERTURBATION,
                            center=(square.center[0],
                                    square.center[1] + ROUND_OFF_PERTURBATION))
        for square in scene.squares))


@cache
def reference_run(solver: str) -> Trajectory:
    """The golden run with ``solver``, computed once per test process."""
    return GOLDEN_RUN.run(solver)


@pytest.mark.parametrize("solver", GOLDEN_SOLVERS)
def test_two_runs_in_one_process_are_bit_identical(solver: str) -> None:
    first = reference_run(solver)
    second = GOLDEN_RUN.run(solver)
    assert first.metrics["n_contacts"].min() > 0  # the run exercises contacts throughout
    assert exact_digest(second) == exact_digest(first)


@pytest.fixture(scope="module")
def fresh_interpreter_digests() -> dict[str, str]:
    """Exact digests of the reference runs computed in one fresh interpreter."""
    code = ("import json\n"
            "from wuerfel_cvx.lab.robustness.determinism import GOLDEN_RUN, GOLDEN_SOLVERS, "
            "exact_digest\n"
            "print(json.dumps({s: exact_digest(GOLDEN_RUN.run(s)) for s in GOLDEN_SOLVERS}))\n")
    # Another hash seed: no result may depend on the iteration order of sets or dicts.
    env = {**os.environ, "PYTHONHASHSEED": "12345"}
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            env=env, timeout=600, check=True)
    digests: dict[str, str] = json.loads(result.stdout.strip().splitlines()[-1])
    return digests


@pytest.mark.subprocess
@pytest.mark.parametrize("solver", GOLDEN_SOLVERS)
def test_a_fresh_interpreter_gives_the_same_bits(
        solver: str, fresh_interpreter_digests: dict[str, str]) -> None:
    assert fresh_interpreter_digests[solver] == exact_digest(reference_run(solver))


@pytest.mark.parametrize("solver", GOLDEN_SOLVERS)
def test_golden_digest_of_the_reference_run(solver: str) -> None:
    golden = tomllib.loads(GOLDEN_FILE.read_text())
    run = golden["run"]
    assert (run["scene"], run["dt"], run["steps"], run["tol"], run["decimals"]) == (
        GOLDEN_RUN.scene, GOLDEN_RUN.dt, GOLDEN_RUN.steps, GOLDEN_RUN.tol, GOLDEN_DECIMALS)
    entry = golden["solvers"][solver]
    installed = pinned_versions(solver)
    if installed != entry["versions"]:
        pytest.skip(f"golden digest recorded with {entry['versions']}, installed {installed}")
    assert rounded_digest(reference_run(solver).points) == entry["sha256"], (
        "the reference run changed by more than 1e-9 m; if that is intended, regenerate "
        "tests/golden/trajectory_hashes.toml (see its header)")


PINNED_VARIANTS = ([("formulations", name) for name in FORMULATIONS]
                   + [("friction", model) for model in FRICTION_MODELS])
"""The golden file's runs with :data:`FORMULATION_SOLVER` beside the reference run: every
formulation's run of ``FORMULATION_RUN`` and every friction model's of ``FRICTION_SCENE``."""


@pytest.mark.parametrize(("section", "name"), PINNED_VARIANTS)
def test_golden_digest_of_every_formulation_and_friction_model(section: str, name: str) -> None:
    """Every formulation's and friction model's run is pinned too.

    So a changed meaning of a name that is not the default's (``rigid``'s rows, say) changes
    the physics fingerprint, and so does a change of ``ccp``'s rows or of the Coulomb fixed
    point, which the frictionless reference run does not reach.
    """
    golden = tomllib.loads(GOLDEN_FILE.read_text())
    if pinned_versions(FORMULATION_SOLVER) != golden["solvers"][FORMULATION_SOLVER]["versions"]:
        pytest.skip(f"golden digests recorded with other versions of {FORMULATION_SOLVER}'s")
    scene, digest = ((FORMULATION_RUN.scene, formulation_digest(name))
                     if section == "formulations" else (FRICTION_SCENE, friction_digest(name)))
    assert digest == golden[section][name]["sha256"], (
        f"{name}'s run of {scene} changed by more than 1e-9 m; if that is intended, "
        "regenerate tests/golden/trajectory_hashes.toml (see its header)")


@pytest.mark.parametrize("model", FRICTION_MODELS)
def test_round_off_stays_far_below_the_golden_rounding_with_friction(model: str) -> None:
    """The friction runs keep the rounding's margin too (see the frictionless test below).

    A 1e-15 change of the start moves ``ccp``'s run by about 4e-14 m and the Coulomb fixed
    point's by about 2e-15 m (its stopping test did not flip); 1e-11 m is two orders below
    the 1e-9 m rounding step.
    """
    scene = Scene.named(FRICTION_SCENE)
    runs = [simulate(start, dt=GOLDEN_RUN.dt, steps=GOLDEN_RUN.steps, solver=FORMULATION_SOLVER,
                     tol=GOLDEN_RUN.tol, friction_model=model)
            for start in (scene, perturbed_start(scene))]
    assert 0.0 < largest_difference(*runs) < 1e-11


@pytest.mark.parametrize("solver", GOLDEN_SOLVERS)
def test_round_off_differences_stay_far_below_the_golden_rounding(solver: str) -> None:
    """Justifies rounding to 1e-9 m: a few-ulp change of the start moves the run by far less.

    Shifting every square's angle by 1e-15 rad and its height by 1e-15 m stands for what
    another machine's arithmetic could change; over the 100 steps the positions must
    stay within 1e-11 m of the reference, two orders below the 1e-9 m rounding step of
    the golden digest.  OSQP and PIQP move by 1e-14 m or less; Clarabel, updated in place
    on the native path, keeps the equilibration of its set-up, which amplifies input
    round-off to about 2e-12 m (set up afresh for every QP: 3e-14 m, at 1.5 to 5 times
    the solve time).
    """
    scene = Scene.named(GOLDEN_RUN.scene)
    perturbed = simulate(perturbed_start(scene), dt=GOLDEN_RUN.dt,
                         steps=GOLDEN_RUN.steps, solver=solver, tol=GOLDEN_RUN.tol)
    difference = largest_difference(perturbed, reference_run(solver))
    assert 0.0 < difference < 1e-11  # > 0: the perturbation did reach the run


def test_the_physics_fingerprint_is_the_golden_files() -> None:
    """A report's physics fingerprint names the golden file's digest set.

    Computed from the golden runs run now, it equals the golden file's when the pinned
    versions are installed; one changed digest changes it.
    """
    golden = tomllib.loads(GOLDEN_FILE.read_text())
    for solver in GOLDEN_SOLVERS:
        if pinned_versions(solver) != golden["solvers"][solver]["versions"]:
            pytest.skip(f"golden digests recorded with other versions of {solver}'s packages")
    expected = golden_fingerprint(GOLDEN_FILE.read_text())
    assert physics_fingerprint() == expected
    digests = ({solver: entry["sha256"] for solver, entry in golden["solvers"].items()}
               | {f"formulation:{name}": entry["sha256"]
                  for name, entry in golden["formulations"].items()}
               | {f"friction:{name}": entry["sha256"]
                  for name, entry in golden["friction"].items()})
    assert fingerprint_of(digests) == expected
    assert fingerprint_of({**digests, "OSQP": "0" * 64}) != expected
    assert fingerprint_of({**digests, "formulation:rigid-baumgarte": "0" * 64}) != expected
    assert fingerprint_of({**digests, "friction:coulomb": "0" * 64}) != expected
