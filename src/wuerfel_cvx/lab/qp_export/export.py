"""Write a suite's step QPs as a qpbenchmark test set (``wuerfel-cvx export-qps``).

The test set's folder holds::

    DIR/wuerfel_step_qps.py     the test set (class WuerfelStepQps(qpbenchmark.TestSet))
    DIR/problems/NAME.npz       one qpsolvers.Problem file per step QP (see .problem)
    DIR/problems.csv            per problem: where it comes from, its size, active set,
                                condition estimate and the reference objective
    DIR/ours.csv                with ``ours=True``: each QP solved by wuerfel_cvx's own
                                solve path with every installed solver and tolerance

A problem's name is ``SCENE_FORMULATION_RATEhz_sSTEP_TAGS``: the scene, the formulation
(with the friction model for a scene with friction, ``rod6`` for the sixth rod), the time
step as a rate (``100hz`` for dt = 0.01 s), the step whose QP it is, and the tags of
:meth:`.features.Features.tags` (``table1e9kg``, ``ratio1e3``, ``degenerate``, ``overlap``,
``cone``, or ``contact``), with ``_iN`` before the tags for a step's N-th island QP.
"""

from __future__ import annotations

import csv
import shutil
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path

from ..bench.suite import Suite
from .capture import CapturedQP, capture_suite, run_settings
from .features import Features, features
from .ours import OURS_FILE, write_ours
from .problem import objective_value, qpsolvers_form, save_problem

TEST_SET_FILE = "wuerfel_step_qps.py"
PROBLEMS_DIR = "problems"
MANIFEST_FILE = "problems.csv"


@dataclass(frozen=True)
class ExportSummary:
    """What an export wrote."""

    out: Path
    problems: int
    runs: int
    test_set: Path
    manifest: Path
    ours: Path | None


def problem_name(captured: CapturedQP, feature: Features) -> str:
    """The problem's name (the module docstring)."""
    setting = captured.setting
    parts = [setting.scene, setting.label(captured.has_friction), f"{round(1 / setting.dt)}hz",
             f"s{captured.step:04d}"]
    if captured.island:
        parts.append(f"i{captured.island}")
    parts.append("-".join(feature.tags(setting.table_mass)))
    return "_".join(parts)


def manifest_row(name: str, captured: CapturedQP, feature: Features,
                 objective: float) -> dict[str, object]:
    """One row of ``problems.csv``."""
    setting = captured.setting
    return {"name": name, "scene": setting.scene, "formulation": setting.formulation,
            "friction_model": setting.friction_model if captured.has_friction else "",
            "dt_s": setting.dt, "table_mass_kg": setting.table_mass or "",
            "extra_rod": setting.extra_rod, "step": captured.step, "island": captured.island,
            **asdict(feature), "degenerate": feature.degenerate,
            "tags": "-".join(feature.tags(setting.table_mass)),
            "reference_solver": captured.solution.solver,
            "reference_verified": captured.solution.verified,
            "reference_objective": objective}


def export_qps(suite: Suite, out: Path, *, scene: str | None = None, steps: int | None = None,
               every: int = 1, ours: bool = False,
               say: Callable[[str], None] = lambda text: None) -> ExportSummary:
    """Run ``suite``'s settings, write their step QPs to ``out`` as a qpbenchmark test set.

    ``scene`` keeps one scene's runs, ``steps`` caps each run's steps and ``every`` keeps
    every ``every``-th step (:mod:`.capture`).  Problem files of an earlier export in
    ``out/problems`` are removed first, so the folder holds this export only.  With
    ``ours``, each QP is also solved by the package's own solve path (:mod:`.ours`).
    """
    settings = run_settings(suite, scene)
    problems = out / PROBLEMS_DIR
    if problems.is_dir():
        shutil.rmtree(problems)
    problems.mkdir(parents=True)
    rows, kept = [], []
    for captured in _announced(capture_suite(settings, steps, every), say):
        data = qpsolvers_form(captured.qp)
        feature = features(captured.qp, data, captured.solution.x)
        name = problem_name(captured, feature)
        if (problems / f"{name}.npz").exists():
            raise RuntimeError(f"two exported QPs are both named {name}")
        save_problem(problems / name, data)
        rows.append(manifest_row(name, captured, feature,
                                 objective_value(data, captured.solution.x)))
        kept.append((name, captured))
    manifest = out / MANIFEST_FILE
    _write_csv(manifest, rows)
    test_set = out / TEST_SET_FILE
    source = resources.files("wuerfel_cvx.lab.qp_export").joinpath(TEST_SET_FILE)
    test_set.write_text(source.read_text(encoding="utf-8"), encoding="utf-8")
    ours_path = write_ours(out / OURS_FILE, kept, say) if ours else None
    return ExportSummary(out, len(rows), len(settings), test_set, manifest, ours_path)


def _announced(captured: Iterable[CapturedQP],
               say: Callable[[str], None]) -> Iterable[CapturedQP]:
    """``captured``, saying when each run's first QP arrives."""
    last = None
    for item in captured:
        if item.setting != last:
            say(f"recording {item.setting.scene} ({item.setting.label(item.has_friction)}, "
                f"dt {item.setting.dt:g} s)")
            last = item.setting
        yield item


def _write_csv(path: Path, rows: list[dict[str, object]]) -> None:
    """Write ``rows`` (dicts with the same keys) as a CSV file with a header."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as handle:
        if not rows:
            return
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
