#!/usr/bin/env bash
# Regenerates reports/dask's measurements: `wuerfel-cvx bench` with `--jobs 2` against
# `--dask 2`, in turn, on the standard subset (standard-dt0.02.toml) and on the overhead
# suites (one-step.toml, one-point.toml).  Writes timings-standard.csv and
# timings-overhead.csv (one line per command: wall seconds as /usr/bin/time measures them),
# keeps the first round's standard-subset rows as results-jobs2.csv and results-dask2.csv,
# and compares their physics columns cell by cell.  ROUNDS=0 leaves the standard subset's
# files as they are and measures the overhead only.
# Run from the repository root:  bash reports/dask/measure.sh [ROUNDS] [OVERHEAD_ROUNDS]
set -euo pipefail
here=reports/dask
rounds=${1:-2}
overhead_rounds=${2:-3}
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
header="round,suite,executor,points,wall_s,load_1min"

run() {  # run TIMINGS ROUND SUITE EXECUTOR-FLAGS...
    local timings=$1 round=$2 suite=$3; shift 3
    local name=$(basename "$suite" .toml) executor=${1#--}$2
    local out=$scratch/$name-$executor-$round
    local load=$(cut -d' ' -f1 /proc/loadavg)
    /usr/bin/time -f %e -o "$scratch/wall" \
        wuerfel-cvx bench --suite "$suite" --out "$out" --no-progress "$@" > /dev/null 2>&1
    local points=$(($(wc -l < "$out/results.csv") - 1))
    echo "$round,$name,$executor,$points,$(cat "$scratch/wall"),$load" >> "$timings"
}

if (( rounds > 0 )); then
    echo "$header" > $here/timings-standard.csv
    for round in $(seq 1 "$rounds"); do  # alternate which executor goes first
        if (( round % 2 )); then order=("--jobs 2" "--dask 2"); else order=("--dask 2" "--jobs 2"); fi
        for flags in "${order[@]}"; do
            run $here/timings-standard.csv "$round" $here/standard-dt0.02.toml $flags
        done
    done
    cp "$scratch/standard-dt0.02-jobs2-1/results.csv" $here/results-jobs2.csv
    cp "$scratch/standard-dt0.02-dask2-1/results.csv" $here/results-dask2.csv
fi
echo "$header" > $here/timings-overhead.csv
for round in $(seq 1 "$overhead_rounds"); do
    for suite in one-step one-point; do
        for flags in "--jobs 2" "--dask 2"; do
            run $here/timings-overhead.csv "$round" $here/$suite.toml $flags
        done
    done
done

python - "$here" <<'PY'
"""The physics columns of the two standard-subset runs, compared cell by cell as written."""
import sys
from pathlib import Path

import pandas as pd

from wuerfel_cvx.lab.bench.schema import CLOCK_COLUMNS

here = Path(sys.argv[1])
frames = [pd.read_csv(here / f"results-{name}.csv", dtype=str, keep_default_na=False)
          .set_index("point_id").sort_index() for name in ("jobs2", "dask2")]
assert list(frames[0].index) == list(frames[1].index), "different point ids"
physics = [column for column in frames[0].columns if column not in CLOCK_COLUMNS]
differing = {column: int((frames[0][column] != frames[1][column]).sum()) for column in physics}
differing = {column: count for column, count in differing.items() if count}
print(f"{len(frames[0])} points, {len(physics)} physics columns, cells differing: "
      f"{differing or 'none'}")
PY
python $here/summarize.py $here
