"""``reports/robustness.md``: generated scenes, fuzzed files, injected faults, fixed bugs.

:func:`write_robustness_report` runs the three checks of this package and renders one
Markdown page, stamped with date, versions and CPU:

- :func:`~wuerfel_cvx.lab.robustness.properties.run_property_sweep`: random valid scenes,
  each run checked against the physical invariants;
- :func:`~wuerfel_cvx.lab.robustness.fuzz.run_fuzz`: mutated scene files, each ending in a
  valid scene, one clear input error, or a clear step failure;
- :func:`~wuerfel_cvx.lab.robustness.faults.run_fault_injections`: solver faults, each
  ending in a clear step failure with a loadable partial run, or a recorded fallback.

The bugs these checks found during development are kept in :data:`FIXED_BUGS`, each
with the regression test that pins it, and rendered into the page.
"""

from __future__ import annotations

import datetime
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ...versions import package_version
from .faults import FaultOutcome, run_fault_injections
from .fuzz import FuzzResult, run_fuzz
from .properties import PropertySweepResult, run_property_sweep


@dataclass(frozen=True)
class FixedBug:
    """A bug found by the robustness checks, how it was fixed, and what pins it."""

    found_by: str
    """``fuzz``, ``fault injection``, ``limits probe`` or ``review``."""
    symptom: str
    fix: str
    test: str
    """The regression test (pytest node id, relative to the repository)."""


FIXED_BUGS: tuple[FixedBug, ...] = (
    FixedBug("fuzz", "Arrays or inline tables nested ~1000 deep crashed the loader with "
             "RecursionError (tomllib parses them recursively): a traceback, exit 1.",
             "`Scene.from_toml` turns it into InputError 'malformed TOML (arrays or tables "
             "nested too deeply)'.",
             "tests/test_robust_input.py::test_regression_input_is_one_clear_input_error"
             "[deep-array-nesting]"),
    FixedBug("fuzz", "An integer beyond 1.8e308 (valid TOML: tomllib has no size limit) "
             "crashed with OverflowError in float().",
             "InputError 'out of range' naming the field.",
             "tests/test_robust_input.py::test_regression_input_is_one_clear_input_error"
             "[integer-beyond-double-range]"),
    FixedBug("fuzz", "Sizes, positions, masses, speeds or gravity of 1e308 or 1e-308 "
             "loaded; the first step then failed with a misleading solver status "
             "('exception: Problem data contains NaN', a false 'infeasible', "
             "'solver_error') or, for a 1e308 table centre, ran on overflowed geometry.",
             "`scene.LIMITS`: every coordinate and length within 1e6 m (sides at least "
             "1e-6 m), masses 1e-6 to 1e6 kg, speeds, spins and gravity within 1e6; "
             "outside, an InputError naming field, bound and unit.",
             "tests/test_robust_input.py::test_regression_input_is_one_clear_input_error"
             "[size-1e308]"),
    FixedBug("fuzz", "The overlap check tested every pair of bodies: a file of 2000 "
             "squares took 5.3 s to load (quadratic: minutes for 10 000).",
             "Candidate pairs from a KD-tree on square centres: 0.19 s for 2000.",
             "tests/test_robust_input.py::test_overlap_check_of_a_large_scene_is_not_quadratic"),
    FixedBug("fuzz", "Unknown keys made of invisible characters (a right-to-left "
             "override, a BOM, the empty key) were printed raw in the one-line error, "
             "scrambling or blanking it.",
             "Keys that are not bare TOML keys are quoted with escapes.",
             "tests/test_robust_input.py::test_regression_input_is_one_clear_input_error"
             "[rtl-override-key]"),
    FixedBug("limits probe", "`--dt 1e-300` ran and exited 0: Baumgarte's beta/dt "
             "turned round-off into speed (the tilted drop gained 9e6 J in one step); "
             "`--dt 1e300` overflowed the contact reach.",
             "`simulate.DT_RANGE`: dt between 1e-6 and 100 s, else InputError.",
             "tests/test_robust_input.py::test_dt_outside_its_range_is_an_input_error"),
    FixedBug("fault injection", "NaN in a step's QP on the compiled direct path (CLARABEL, "
             "OSQP, from step 3) escaped as a bare ValueError ('Parameter value must be "
             "real'): no StepFailure, no partial trajectory saved.",
             "`solve_step_qp` checks the QP data first (status 'invalid_data', naming the "
             "array) and applies compiled parameters inside its error handling.",
             "tests/test_solver_faults.py::test_nan_in_the_qp_data_stops_before_any_solver"),
    FixedBug("review", "`Residuals.worst()` used max(), which skips a NaN after the first "
             "argument: a solution with NaN multipliers counted as verified.",
             "`worst()` is inf if any residual is NaN.",
             "tests/test_solver_faults.py::test_nan_multipliers_make_a_step_unverified"),
)

#: Solver faults and bad inputs that are documented behaviour rather than bugs.
KNOWN_LIMITS = (
    "Overlapping squares with stabilisation off (beta = 0, push_speed = 0) do not give an "
    "infeasible step: every row of the velocity QP is then satisfied by v+ = 0.  The "
    "infeasible step of the fault table is a square squeezed by two walls with push-out on "
    "(HiGHS confirms "
    "infeasibility independently: tests/test_solver_faults.py::"
    "test_squeezed_square_is_truly_infeasible); no solver or fallback can solve it.",
    "At the far ends of the accepted ranges CLARABEL reported a false 'infeasible' (a "
    "unit square at 1e6 m/s over a table, a 1000 m square spinning at 1000 rad/s); such "
    "step QPs are now solved in scaled units (wuerfel_cvx.solve.scaling), see "
    "docs/false-infeasible.md.",
    "A step on the closest-approach rows (rigid, the default, and velocity) that reaches "
    "its limit of 8 Gauss-Newton passes without its gaps within gap_tolerance of their "
    "ramps keeps its last solution; its penetration can then exceed the bound, and the "
    "property check reports it in the table of generated scenes above "
    "(docs/closest-approach.md).",
    "A fallback is not tried on NaN data ('invalid_data'): the same data fails every solver.",
    "Found by the property checks and fixed by the per-pair contact rule: where corners of "
    "two squares overlap by 1e-9 to 4e-7 m, the per-corner edge rule paired them with faces "
    "whose push-outs nearly contradicted each other, and Baumgarte's push-out added 4e-5 to "
    "2e-3 J per step (1 of 800 generated scenes, 1 of 110 hypothesis examples).  Both "
    "scenes now pass every check, with either velocity variant: "
    "tests/test_properties.py::test_no_energy_leak_at_overlapping_corners.",
)


@dataclass(frozen=True)
class RobustnessRun:
    """The results of one ``wuerfel-cvx robustness`` run."""

    properties: PropertySweepResult
    fuzz: FuzzResult
    faults: list[FaultOutcome]
    seed: int
    command: str
    seconds: float


def run_robustness(scenes: int, fuzz: int, seed: int, *, steps: int = 200,
                   crash_dir: Path | None = None, command: str = "",
                   say: Callable[[str], None] = lambda text: None) -> RobustnessRun:
    """Run the property sweep, the fuzzer and the fault injections."""
    started = time.perf_counter()
    say(f"property sweep: {scenes} generated scenes of {steps} steps ...")
    properties = run_property_sweep(scenes, seed, steps=steps)
    say(f"fuzz: {fuzz} mutated scene files ...")
    fuzzed = run_fuzz(fuzz, seed, crash_dir=crash_dir)
    say("fault injection ...")
    faults = run_fault_injections()
    return RobustnessRun(properties, fuzzed, faults, seed, command,
                         time.perf_counter() - started)


def write_robustness_report(out: Path, scenes: int, fuzz: int, seed: int, *,
                            steps: int = 200, command: str = "",
                            say: Callable[[str], None] = lambda text: None) -> Path:
    """Run every check and write the report to ``out``; crashing inputs go beside it."""
    crash_dir = out.with_name(out.stem + "-crashes")
    run = run_robustness(scenes, fuzz, seed, steps=steps, crash_dir=crash_dir,
                         command=command, say=say)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render(run), encoding="utf-8")
    return out


# ---------------------------------------------------------------------- rendering
def render(run: RobustnessRun) -> str:
    """The Markdown page of one run."""
    sweep, fuzz = run.properties, run.fuzz
    lines = [
        "# Robustness",
        "",
        f"Generated by `{run.command or 'wuerfel-cvx robustness'}`; do not edit by hand.",
        "",
        *_stamp(run),
        "",
        "## Summary",
        "",
        "| check | tried | passed | failed | time (s) |",
        "|---|---:|---:|---:|---:|",
        f"| generated scenes, {sweep.steps} steps of {sweep.dt:g} s each, checked against "
        f"the invariants | {sweep.tried} | {sweep.tried - len(sweep.failures)} | "
        f"{len(sweep.failures)} | {sweep.seconds:.0f} |",
        f"| fuzzed scene files (valid scene, clear input error or clear step failure) | "
        f"{fuzz.tried} | {fuzz.tried - len(fuzz.crashes)} | {len(fuzz.crashes)} | "
        f"{fuzz.seconds:.0f} |",
        f"| injected solver faults (clear step failure with a loadable partial run, or "
        f"a recorded fallback) | {len(run.faults)} | "
        f"{sum(_fault_ok(f) for f in run.faults)} | "
        f"{sum(not _fault_ok(f) for f in run.faults)} | |",
        "",
        *_properties_section(sweep),
        *_fuzz_section(fuzz),
        *_faults_section(run.faults),
        *_bugs_section(),
        "## Known limits",
        "",
        *[f"- {text}" for text in KNOWN_LIMITS],
        "",
    ]
    return "\n".join(lines)


def _stamp(run: RobustnessRun) -> list[str]:
    from ..bench.report import current_provenance_line
    from ..bench.runner import machine

    packages = ("wuerfel_cvx", "cvxpy", "clarabel", "osqp", "piqp", "numpy", "scipy")
    versions = ", ".join(f"{name} {package_version(name)}" for name in packages)
    now = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
    return [
        f"- **Date:** {now}",
        f"- **Seed:** {run.seed} (the same seed gives the same scenes and files)",
        f"- **CPU:** {machine()['cpu']}",
        f"- **Python:** {platform.python_version()} ({platform.system()})",
        f"- **Versions:** {versions}",
        f"- **Total time:** {run.seconds:.0f} s",
        current_provenance_line(),
    ]


def _properties_section(sweep: PropertySweepResult) -> list[str]:
    lines = ["## Generated scenes", "",
             f"{sweep.tried} random valid scenes (seed {sweep.seed}; 1 to 8 squares and boxes of "
             "random size, aspect, mass, angle, velocity and spin above a table), each "
             "simulated for "
             f"{sweep.steps} steps with CLARABEL and checked for NaN, rod drift, "
             "penetration and energy against the bounds derived in "
             "`wuerfel_cvx.lab.robustness.bounds`.", ""]
    if not sweep.failures:
        return lines + ["Every scene kept every invariant.", ""]
    lines += ["| scene | problems |", "|---|---|"]
    for failure in sweep.failures:
        problems = "; ".join(failure.problems).replace("|", "/")
        lines.append(f"| {failure.index} | {problems} |")
    return lines + [""]


def _fuzz_section(fuzz: FuzzResult) -> list[str]:
    lines = [
        "## Fuzzed scene files", "",
        f"{fuzz.tried} mutations of library scene files (wrong types, missing and unknown "
        "keys, huge, tiny, infinite and NaN numbers, big integers, unicode, deep nesting, "
        "flipped bytes, truncation, megabytes of comments, hundreds of squares or boxes), each "
        "loaded and, if it loads, simulated for one step.", "",
        "| outcome | files |", "|---|---:|",
        f"| valid scene, stepped to a finite state | {fuzz.accepted} |",
        f"| rejected: one-line input error naming file and field (exit status 2) | "
        f"{fuzz.rejected} |",
        f"| loaded, first step failed with step, solver and status (exit status 1) | "
        f"{fuzz.step_failures} |",
        f"| **crash** (anything else) | {len(fuzz.crashes)} |", "",
    ]
    if fuzz.step_failure_statuses:
        lines += ["Step failures by status: " + ", ".join(
            f"'{status}' {count}" for status, count in fuzz.step_failure_statuses.most_common())
            + ".  A scene with `allow_overlap = true` may start in an overlap that no "
            "velocity can resolve (like the squeezed square below); each failure is re-run "
            "with the other solvers as a cross-check.", "",
            "| input | mutation | message |", "|---:|---|---|"]
        lines += [f"| {index} | {label.replace('|', '/')} | {detail.replace('|', '/')} |"
                  for index, label, detail in fuzz.step_failure_examples]
        lines.append("")
    lines += ["Most frequent rejections:", "", "| reason | files |", "|---|---:|"]
    lines += [f"| {reason.replace('|', '/')} | {count} |"
              for reason, count in fuzz.rejection_reasons.most_common(15)]
    lines.append("")
    if fuzz.crashes:
        lines += ["Crashes (inputs saved for reproduction):", "",
                  "| input | mutation | error | saved |", "|---:|---|---|---|"]
        lines += [f"| {c.index} | {c.label.replace('|', '/')} | {c.error.replace('|', '/')} | "
                  f"{c.saved or ''} |" for c in fuzz.crashes]
        lines.append("")
    return lines


def _fault_ok(outcome: FaultOutcome) -> bool:
    clear = (outcome.outcome.startswith("StepFailure: step ")
             and "failed with status '" in outcome.outcome)
    return (clear or outcome.outcome.startswith("completed")) and outcome.reloaded


def _faults_section(faults: list[FaultOutcome]) -> list[str]:
    lines = ["## Injected solver faults", "",
             "Each run uses CLARABEL; `fallback` is `simulate(..., fallback=...)` "
             "(`--fallback NAME`).  'kept' is the number of steps in the trajectory returned "
             "or carried by the StepFailure; 'reloads' says it was saved and loaded back "
             "with those steps, all finite.", "",
             "| fault | fallback | outcome | kept | reloads |", "|---|---|---|---:|---|"]
    for f in faults:
        lines.append(f"| {f.fault} | {', '.join(f.fallback) or '-'} | "
                     f"{f.outcome.replace('|', '/')} | {f.steps_kept} | "
                     f"{'yes' if f.reloaded else '**no**'} |")
    return lines + [""]


def _bugs_section() -> list[str]:
    lines = ["## Bugs found and fixed", "",
             "| found by | symptom | fix | regression test |", "|---|---|---|---|"]
    for bug in FIXED_BUGS:
        lines.append(f"| {bug.found_by} | {bug.symptom} | {bug.fix} | `{bug.test}` |")
    return lines + [""]
