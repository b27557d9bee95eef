"""Step QPs as a public test set: ``wuerfel-cvx export-qps`` writes them for qpbenchmark.

:mod:`.capture` records the step QPs of a suite's runs, :mod:`.problem` writes each as a
``qpsolvers.Problem`` file, :mod:`.features` measures what makes it hard (active set,
condition estimate, mass ratio, overlap), :mod:`.export` writes the folder with the test
set module ``wuerfel_step_qps.py`` (the class ``WuerfelStepQps(qpbenchmark.TestSet)``),
and :mod:`.ours` solves the same QPs with the package's own solve path for comparison.
qpbenchmark itself is needed only to run the set (the ``qpbenchmark`` extra).
"""

from __future__ import annotations

from .capture import CapturedQP, RunSetting, capture_run, run_settings
from .export import ExportSummary, export_qps, problem_name
from .features import Features, features
from .problem import QPData, load_problem, qpsolvers_form, save_problem

__all__ = ["CapturedQP", "ExportSummary", "Features", "QPData", "RunSetting", "capture_run",
           "export_qps", "features", "load_problem", "problem_name", "qpsolvers_form",
           "run_settings", "save_problem"]
