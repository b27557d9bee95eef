"""Benchmark suite files (TOML), installed as the package data ``wuerfel_cvx.suites``."""
