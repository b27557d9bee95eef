"""Every notebook in notebooks/ runs top to bottom in smoke mode (WUERFEL_SMOKE=1).

The notebooks are executed in memory with nbclient on this interpreter's ``python3``
kernel (ipykernel); the committed files are not changed.  Each notebook has a time
limit; a cell that raises fails the test with the cell's traceback.
"""

from __future__ import annotations

import time
from pathlib import Path

import nbclient  # in the test extra: a missing install fails here, not as a silent skip
import nbformat
import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))

NOTEBOOK_TIME_LIMIT_S = 600.0
"""Wall time allowed per notebook in smoke mode: a hang guard (they take well under a
minute on 2 cores), not a performance assertion."""

COMMITTED_SIZE_LIMIT_BYTES = 1_000_000
"""Committed notebooks hold small outputs only."""


@pytest.mark.integration
@pytest.mark.subprocess  # each notebook runs in its own kernel process
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[path.stem for path in NOTEBOOKS])
def test_notebook_runs_in_smoke_mode(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WUERFEL_SMOKE", "1")  # the kernel inherits this environment
    notebook = nbformat.read(path, as_version=4)
    deadline = time.monotonic() + NOTEBOOK_TIME_LIMIT_S

    def remaining(_cell: object) -> int:  # each cell gets what is left of the notebook's limit
        return max(1, int(deadline - time.monotonic()))

    client = nbclient.NotebookClient(notebook, kernel_name="python3", timeout_func=remaining,
                                     resources={"metadata": {"path": str(path.parent)}})
    client.execute()
    errors = [output for cell in notebook.cells if cell.cell_type == "code"
              for output in cell.outputs if output.output_type == "error"]
    assert not errors


@pytest.mark.unit
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[path.stem for path in NOTEBOOKS])
def test_committed_notebook_is_small(path: Path) -> None:
    assert path.stat().st_size < COMMITTED_SIZE_LIMIT_BYTES


@pytest.mark.unit
def test_notebooks_are_found() -> None:
    assert NOTEBOOKS, "no notebooks found in notebooks/"
