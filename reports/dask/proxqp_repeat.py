"""The control for results-jobs2.csv against results-dask2.csv: a point run twice in one process.

For every point whose physics cells differ between the two files, run the point twice here,
in this one process and without any pool or cluster, and count the physics cells in which
those two runs differ.  A point that differs here too is not reproducible run to run, so its
rows cannot be expected to agree between executors either.  Prints a markdown table.
Run from the repository root:  python reports/dask/proxqp_repeat.py
"""

from __future__ import annotations

import csv
from pathlib import Path

import pandas as pd

from wuerfel_cvx.lab.bench import schema
from wuerfel_cvx.lab.bench.runner import run_point, run_reference
from wuerfel_cvx.lab.bench.suite import Suite

HERE = Path(__file__).parent


def written(row: dict[str, object]) -> pd.Series:
    """A row's cells as the results file writes them."""
    cells = next(csv.reader([schema.format_row(row)]))
    return pd.Series(cells, index=list(schema.COLUMN_NAMES))


def main() -> None:
    """Print, per differing point, the differing cells across executors and within one process."""
    frames = [pd.read_csv(HERE / f"results-{name}.csv", dtype=str, keep_default_na=False)
              .set_index("point_id").sort_index() for name in ("jobs2", "dask2")]
    physics = [column for column in frames[0].columns if column not in schema.CLOCK_COLUMNS]
    differs = (frames[0][physics] != frames[1][physics]).sum(axis=1)
    points = {p.point_id: p for p in Suite.from_toml(HERE / "standard-dt0.02.toml").points}
    print("| point | cells differing, --jobs 2 vs --dask 2 | cells differing, "
          "two runs in one process |")
    print("| --- | ---: | ---: |")
    for point_id in differs[differs > 0].index:
        point = points[point_id]
        key = point.reference_key
        reference = run_reference(key) if key is not None else None
        first, second = (written(run_point(point, reference))[physics] for _ in range(2))
        print(f"| `{point_id}` | {differs[point_id]} | {int((first != second).sum())} |")


if __name__ == "__main__":
    main()
