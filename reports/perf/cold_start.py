"""What the README's demo waits for beyond its steps: a fresh process's start.

``wuerfel-cvx simulate tilted-drop --steps 300`` steps for about 0.1 s; the process around it
imports the package's dependencies and loads the compiled loops numba cached at the first
run after the install.  This times, each in a fresh interpreter, ``RUNS`` times:

- the demo command as a user runs it (whole process, wall seconds);
- within one process: importing ``wuerfel_cvx.simulate``, the first ``simulate()`` of
  tilted-drop (300 steps: numba loads its cached loops on first use), and a second one
  (the steps alone), and whether cvxpy was imported;
- ``import cvxpy`` alone after the modules the native path needs, which the native path
  does without (only the ``compiled`` and ``declared`` paths import it).

The compiled loops must be cached already (run the demo once after an install).  Prints a
Markdown table of the minimum, median and maximum over the runs.

``PYTHONPATH=src python reports/perf/cold_start.py > reports/perf/cold-start.md``
"""

from __future__ import annotations

import json
import shutil
import statistics
import subprocess
import sys
import time

RUNS = 7

_IN_PROCESS = """
import json, sys, time
started = time.perf_counter()
from wuerfel_cvx.simulate import simulate
imported = time.perf_counter()
simulate("tilted-drop", steps=300)
first = time.perf_counter()
simulate("tilted-drop", steps=300)
second = time.perf_counter()
print(json.dumps({"import": imported - started, "first": first - imported,
                  "second": second - first, "cvxpy": "cvxpy" in sys.modules}))
"""

_CVXPY_ALONE = """
import json, time
import numba, pandas, scipy.sparse, scipy.spatial, clarabel, osqp, piqp
started = time.perf_counter()
import cvxpy
print(json.dumps({"cvxpy": time.perf_counter() - started}))
"""


def _json_of(code: str) -> dict[str, float]:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    loaded: dict[str, float] = json.loads(done.stdout.splitlines()[-1])
    return loaded


def _demo_seconds() -> float:
    command = shutil.which("wuerfel-cvx")
    argv = ([command] if command else [sys.executable, "-m", "wuerfel_cvx"]) + [
        "simulate", "tilted-drop", "--steps", "300"]
    started = time.perf_counter()
    subprocess.run(argv, capture_output=True, check=True)
    return time.perf_counter() - started


def _cells(values: list[float]) -> str:
    return (f"{min(values):.2f} | {statistics.median(values):.2f} | "
            f"{max(values):.2f}")


def main() -> None:
    """Print the table."""
    _demo_seconds()  # the loops cached, the files in the page cache
    demo, parts, alone = [], [], []
    for _ in range(RUNS):
        demo.append(_demo_seconds())
        parts.append(_json_of(_IN_PROCESS))
        alone.append(_json_of(_CVXPY_ALONE)["cvxpy"])
    print(f"Each row over {RUNS} fresh processes, wall seconds.\n")
    print("| what | min (s) | median (s) | max (s) |")
    print("| --- | ---: | ---: | ---: |")
    print(f"| `wuerfel-cvx simulate tilted-drop --steps 300`, whole process | {_cells(demo)} |")
    for key, label in (("import", "import `wuerfel_cvx.simulate`"),
                       ("first", "first `simulate()` (300 steps, cached loops loaded)"),
                       ("second", "second `simulate()` (the 300 steps alone)")):
        print(f"| {label} | {_cells([part[key] for part in parts])} |")
    print(f"| `import cvxpy` after the native path's modules (not paid by it) | "
          f"{_cells(alone)} |")
    imported = sorted({bool(part["cvxpy"]) for part in parts})
    print(f"\ncvxpy imported by the default run: {', '.join(map(str, imported))}.")


if __name__ == "__main__":
    main()
