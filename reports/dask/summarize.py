"""Summarise reports/dask's timings (written by measure.sh): speed-up and overhead per point.

Prints markdown tables: the median wall time of each suite and executor over the rounds, the
speed-up of ``--dask 2`` over ``--jobs 2`` on the standard subset, each round's ratio (the two
runs of a round ran back to back, so their ratio is the least disturbed by other load), and
the overhead per point: the slope of wall time against points between one-point.toml and
one-step.toml, in which a sweep's fixed costs (interpreter, imports, starting and closing the
pool or the cluster) cancel.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

here = Path(sys.argv[1] if len(sys.argv) > 1 else "reports/dask")
overhead_file = sys.argv[2] if len(sys.argv) > 2 else "timings-overhead.csv"
timings = pd.concat([pd.read_csv(here / "timings-standard.csv"),
                     pd.read_csv(here / overhead_file)])
medians = timings.groupby(["suite", "executor"])[["points", "wall_s", "load_1min"]].median()
print("| suite | executor | points | median wall (s) | rounds | median load |")
print("| --- | --- | ---: | ---: | ---: | ---: |")
for (suite, executor), row in medians.iterrows():
    rounds = len(timings[(timings["suite"] == suite) & (timings["executor"] == executor)])
    print(f"| {suite} | {executor} | {int(row['points'])} | {row['wall_s']:.1f} | {rounds} "
          f"| {row['load_1min']:.1f} |")

subset = timings[timings["suite"] == "standard-dt0.02"].pivot(
    index="round", columns="executor", values="wall_s")
ratios = subset["jobs2"] / subset["dask2"]
print()
print("Standard subset, wall(--jobs 2) / wall(--dask 2) per round: "
      + ", ".join(f"{ratio:.2f}" for ratio in ratios)
      + f"; of the medians: {subset['jobs2'].median() / subset['dask2'].median():.2f}")

print()
print("| executor | fixed cost (s) | per point (ms) |")
print("| --- | ---: | ---: |")
slopes = {}
for executor in ("jobs2", "dask2"):
    one = medians.loc[("one-point", executor)]
    many = medians.loc[("one-step", executor)]
    slope = (many["wall_s"] - one["wall_s"]) / (many["points"] - one["points"])
    slopes[executor] = slope
    print(f"| {executor} | {one['wall_s'] - slope:.1f} | {1e3 * slope:.1f} |")
print()
print(f"Overhead of Dask per point over the pool's: "
      f"{1e3 * (slopes['dask2'] - slopes['jobs2']):.1f} ms")
