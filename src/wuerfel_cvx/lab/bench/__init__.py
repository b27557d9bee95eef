"""Benchmarks: suites of grid points, the sweep that runs them, results, plots and reports."""
