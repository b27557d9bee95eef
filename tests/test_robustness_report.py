"""``wuerfel-cvx robustness``: the report of generated scenes, fuzzed files and faults."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from wuerfel_cvx.cli import main
from wuerfel_cvx.lab.robustness.faults import run_fault_injections
from wuerfel_cvx.lab.robustness.fuzz import Crash, FuzzResult
from wuerfel_cvx.lab.robustness.properties import PropertyFailure, PropertySweepResult
from wuerfel_cvx.lab.robustness.report import (
    FIXED_BUGS,
    KNOWN_LIMITS,
    FixedBug,
    RobustnessRun,
    render,
)

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[1]


def test_command_writes_a_stamped_report_with_every_section(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "reports" / "robustness.md"
    assert main(["robustness", "--scenes", "2", "--fuzz", "20", "--steps", "20",
                 "--seed", "3", "--out", str(out)]) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    text = out.read_text()
    for stamp in ("- **Date:** ", "- **Seed:** 3", "- **CPU:** ", "- **Versions:** wuerfel_cvx",
                  "cvxpy", "clarabel"):
        assert stamp in text
    assert "robustness --scenes 2 --fuzz 20 --steps 20 --seed 3" in text
    summary = re.search(r"\| generated scenes, 20 steps of 0.01 s each[^|]*\| (\d+) \| (\d+) "
                        r"\| (\d+) \|", text)
    assert summary is not None
    tried, passed, failed = map(int, summary.groups())
    assert tried == 2 and passed + failed == 2
    fuzz = re.search(r"\| fuzzed scene files[^|]*\| (\d+) \| (\d+) \| (\d+) \|", text)
    assert fuzz is not None and int(fuzz.group(1)) == 20
    assert int(fuzz.group(2)) + int(fuzz.group(3)) == 20
    for heading in ("## Generated scenes", "## Fuzzed scene files", "## Injected solver faults",
                    "## Bugs found and fixed", "## Known limits"):
        assert heading in text
    for bug in FIXED_BUGS:
        assert bug.test in text
    for limit in KNOWN_LIMITS:
        assert limit in text
    assert not (tmp_path / "reports" / "robustness-crashes").exists()  # nothing crashed


@pytest.mark.parametrize(("flags", "written"), [
    ([], "bench-results/robustness.md"),
    (["--report"], "reports/robustness.md"),
])
def test_the_committed_report_is_written_only_when_asked_for(
        flags: list[str], written: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)  # as from the repository's root
    assert main(["robustness", "--scenes", "1", "--fuzz", "1", "--steps", "2", *flags]) == 0
    assert capsys.readouterr().out == f"wrote {written}\n"
    assert [str(path.relative_to(tmp_path)) for path in tmp_path.rglob("*.md")] == [written]


def test_negative_counts_are_input_errors(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["robustness", "--fuzz", "-1"]) == 2
    assert "--fuzz" in capsys.readouterr().err


@pytest.mark.parametrize("bug", FIXED_BUGS, ids=lambda bug: bug.test.split("::")[-1])
def test_each_fixed_bug_names_a_regression_test_that_exists(bug: FixedBug) -> None:
    test = bug.test
    file, _, node = test.partition("::")
    name, _, param = node.partition("[")
    source = (ROOT / file).read_text()
    assert f"def {name}(" in source
    if param:
        assert f'"{param.rstrip("]")}"' in source


def test_every_injected_fault_ends_clearly() -> None:
    outcomes = run_fault_injections()
    by_fault = {(o.fault, o.fallback): o for o in outcomes}
    assert all(o.reloaded for o in outcomes)
    limit = "iteration limit 1 (CLARABEL, from step 3)"
    assert by_fault[(limit, ())].outcome.endswith("status 'user_limit'")
    assert by_fault[(limit, ())].steps_kept == 2
    assert "after CLARABEL's 'user_limit'" in by_fault[(limit, ("OSQP",))].outcome
    assert by_fault[(limit, ("OSQP",))].steps_kept == 6
    squeezed = "square squeezed by two walls (push-out on)"
    assert "step 1: solver CLARABEL failed with status 'infeasible'" in \
        by_fault[(squeezed, ())].outcome
    assert "then OSQP failed with 'infeasible'" in by_fault[(squeezed, ("OSQP",))].outcome
    assert by_fault[("overlap, stabilisation off (no push-out)", ())].outcome.startswith(
        "completed")
    nan = "NaN in the QP target at step 3"
    assert "'invalid_data' (non-finite target)" in by_fault[(nan, ())].outcome
    raises = "CLARABEL raises (from step 3)"
    assert "'exception' (RuntimeError: injected" in by_fault[(raises, ())].outcome
    assert "after CLARABEL's 'exception'" in by_fault[(raises, ("OSQP",))].outcome


def test_render_lists_crashes_and_broken_invariants() -> None:
    fuzz = FuzzResult(tried=6, accepted=1, rejected=3, step_failures=1,
                      crashes=[Crash(4, "stack-3: set x | y", "ValueError: boom", "c/4.toml")])
    fuzz.step_failure_statuses["infeasible"] += 1
    fuzz.step_failure_examples.append((5, "overlap-recovery: size", "step 1: ...; other"))
    sweep = PropertySweepResult(
        tried=3, failures=[PropertyFailure(1, {}, ("penetration 2e-3 m above bound 1e-9 m",))],
        seconds=1.0, seed=0, steps=50)
    text = render(RobustnessRun(sweep, fuzz, [], 0, "wuerfel-cvx robustness", 1.0))
    assert "| 4 | stack-3: set x / y | ValueError: boom | c/4.toml |" in text
    assert "| 1 | penetration 2e-3 m above bound 1e-9 m |" in text
    assert "| **crash** (anything else) | 1 |" in text
    assert "Step failures by status: 'infeasible' 1." in text
    assert "| 5 | overlap-recovery: size | step 1: ...; other |" in text
    assert "| 3 | 2 | 1 |" in text  # the sweep's tried, passed, failed
