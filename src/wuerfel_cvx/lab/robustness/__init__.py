"""Robustness checks: generated scenes against physical invariants, and fuzzed scene files.

:mod:`wuerfel_cvx.lab.robustness.properties` draws random valid scenes and checks a run of
each against the invariants the package promises (no NaN, rod drift, penetration, energy);
:mod:`wuerfel_cvx.lab.robustness.fuzz` mutates valid scene files and checks that each ends in a
valid scene or the package's one clear input error.  ``wuerfel-cvx robustness`` runs both
and writes ``reports/robustness.md``.
"""
