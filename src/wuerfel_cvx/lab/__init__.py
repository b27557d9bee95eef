"""The laboratory: benchmarks, peer engines, robustness checks and QP export."""
