"""The solver registry: one place for a solver's package, version, style, timing, adapter."""

from __future__ import annotations

import importlib
import math
from importlib.metadata import version

import pytest

from wuerfel_cvx import simulate, versions
from wuerfel_cvx.errors import StepFailure
from wuerfel_cvx.lab.bench import plots
from wuerfel_cvx.solve import registry
from wuerfel_cvx.solve.registry import SOLVERS, Timing, available_solvers

pytestmark = pytest.mark.unit


@pytest.mark.parametrize("solver", available_solvers())
def test_an_installed_solver_reports_its_distribution_version(solver: str) -> None:
    spec = SOLVERS[solver]
    assert spec.version() == version(spec.package)


def test_a_missing_distribution_is_not_installed() -> None:
    assert versions.package_version("no-such-distribution-wuerfel") == versions.NOT_INSTALLED


def test_plots_take_each_solver_style_from_its_spec() -> None:
    for name, spec in SOLVERS.items():
        assert plots.solver_style(name) == spec.style
    styles = [spec.style for spec in SOLVERS.values()]
    assert len(set(styles)) == len(styles)  # no two solvers look alike


def test_each_adapter_is_a_module_with_a_setup() -> None:
    adapted = {name for name, spec in SOLVERS.items() if spec.adapter is not None}
    assert adapted == {"CLARABEL", "OSQP", "PIQP", "PROXQP", "DAQP", "HIGHS"}  # SCS: cvxpy
    for spec in SOLVERS.values():
        if spec.adapter is not None:
            module = importlib.import_module(f"wuerfel_cvx.solve.adapters.{spec.adapter}")
            assert callable(module.setup)
    # cvxpy's interfaces to these pose another problem: their adapters serve every path
    assert ({name for name, spec in SOLVERS.items() if spec.native_only}
            == {"PROXQP", "DAQP", "HIGHS"})


def test_timing_rules() -> None:
    timing = Timing()
    assert timing.solver_time(2e-3, 1e-3) == 1e-3  # the native calls' wall time caps it
    assert timing.solver_time(1e-3, 2e-3) == 1e-3
    assert timing.solver_time(1e-3) == 1e-3  # through cvxpy: the report alone
    assert math.isnan(timing.solver_time(0.0))  # "no time" is unknown, not free
    assert math.isnan(timing.solver_time(math.nan))
    assert Timing(capped_by_native_wall=False).solver_time(2e-3, 1e-3) == 2e-3


def test_a_highs_solve_past_its_time_limit_is_a_failed_step(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """HiGHS's own time limit (HIGHS_TIME_LIMIT) ends a solve that would not end.

    Its QP solver cycled for 15 minutes on one step of rain-10 (registry.HIGHS_TIME_LIMIT);
    here the limit is made too short for any solve with rows (a QP without rows HiGHS
    solves in closed form, before any clock is read: a resting stack has rows from its first
    step), and the step fails with HiGHS's status and its number, as a hung solve now does
    after 60 s.
    """
    if "HIGHS" not in available_solvers():
        pytest.skip("HiGHS is not installed")
    monkeypatch.setattr(registry, "HIGHS_TIME_LIMIT", 0.0)
    with pytest.raises(StepFailure) as failure:
        simulate("stack-5", dt=0.01, steps=3, solver="HIGHS")
    assert failure.value.status == "user_limit" and failure.value.step == 1  # the first


def test_clarabel_runs_on_one_thread_so_that_forked_workers_do_not_hang() -> None:
    """CLARABEL is set to one thread, as every other solver here runs.

    Clarabel's default thread pool, started in a process that then forks (a sweep's
    ``--jobs`` workers), left a worker's parallel factorization waiting forever for the
    pool's threads (the friction suite's 5050-box pyramid).  One thread starts no pool.
    """
    assert all(SOLVERS["CLARABEL"].options(eps)["max_threads"] == 1
               for eps in (1e-4, 1e-7, 1e-9))


def test_the_registry_finds_the_solvers_cvxpy_finds_and_names_statuses_as_cvxpy() -> None:
    import cvxpy as cp

    from wuerfel_cvx.solve.paths import OPTIMAL, OPTIMAL_INACCURATE

    in_cvxpy = set(cp.installed_solvers())
    assert available_solvers() == [name for name, spec in SOLVERS.items()
                                   if spec.cvxpy_name in in_cvxpy]
    assert (OPTIMAL, OPTIMAL_INACCURATE) == (cp.OPTIMAL, cp.OPTIMAL_INACCURATE)
