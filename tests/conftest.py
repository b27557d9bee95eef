"""Shared fixtures and the test-kind check for the whole test suite.

Every test carries at least one of three kinds (registered in ``pyproject.toml``), most
often as a module-level ``pytestmark``:

* ``unit``: pure functions on small inputs, no simulation loop (``pytest -m unit`` is quick);
* ``integration``: runs simulations, benchmark sweeps, reports or the robustness checks;
* ``subprocess``: starts a process (the CLI in a fresh interpreter, worker processes, the
  notebooks' kernels); ``pytest -m "not subprocess"`` leaves them out.

A test without a kind fails, naming what to add, so a new test module cannot forget its
marker.  Helpers that are plain code rather than fixtures live in
importable modules next to this file (``qp_bank.py``, ``oracles.py``): pytest puts
``tests/`` on ``sys.path``, and test modules never import each other.
"""

from __future__ import annotations

import pytest

from wuerfel_cvx import Scene, Square
from wuerfel_cvx.scenes.library import FLOOR

TEST_KINDS = ("unit", "integration", "subprocess")
"""The markers of which every test needs at least one."""


_NO_KIND = pytest.StashKey[bool]()


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects anything
def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Make a test without any of :data:`TEST_KINDS` fail, whichever kinds are selected.

    Such a test is given the ``unit`` and ``integration`` markers so that ``-m unit``,
    ``-m integration`` and ``-m "not subprocess"`` all select it, and it then fails in
    :func:`pytest_runtest_setup` (a plain collection error would stop ``pytest-xdist``
    workers with an internal error instead of naming the test).
    """
    for item in items:
        if not any(item.get_closest_marker(kind) for kind in TEST_KINDS):
            item.stash[_NO_KIND] = True
            item.add_marker(pytest.mark.unit)
            item.add_marker(pytest.mark.integration)


def pytest_runtest_setup(item: pytest.Item) -> None:
    """Fail a test that has no kind marker (see :func:`pytest_collection_modifyitems`)."""
    if item.stash.get(_NO_KIND, False):
        pytest.fail(f"{item.nodeid} has no kind marker: add `pytestmark = pytest.mark.<kind>` "
                    f"to its module or mark the test ({', '.join(TEST_KINDS)}; see "
                    "tests/conftest.py)", pytrace=False)


@pytest.fixture
def two_stacks_and_a_faller() -> Scene:
    """Two 3-stacks 5 m apart, their tops tilted and moving, and a square in free flight."""
    left = [Square(center=(-2.5, 0.5 + k)) for k in range(2)]
    right = [Square(center=(2.5, 0.5 + k)) for k in range(2)]
    tops = [Square(center=(-2.5, 2.56), angle=0.1, velocity=(0.3, -1.0)),
            Square(center=(2.5, 2.6), angle=-0.2, velocity=(-0.2, -2.0), angular_velocity=1.0)]
    faller = Square(center=(0.0, 6.0), velocity=(0.0, -1.0))
    return Scene("two-stacks", (*left, tops[0], *right, tops[1], faller), (FLOOR,))
