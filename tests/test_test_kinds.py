"""The test-kind check of ``tests/conftest.py``: a test without a kind marker fails."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest_plugins = ["pytester"]

pytestmark = pytest.mark.unit

CONFTEST = Path(__file__).with_name("conftest.py")


@pytest.mark.parametrize("selection", [[], ["-m", "unit"], ["-m", "not subprocess"]])
def test_a_test_without_a_kind_fails_whatever_is_selected(pytester: pytest.Pytester,
                                                         selection: list[str]) -> None:
    pytester.makeconftest(CONFTEST.read_text(encoding="utf-8"))
    pytester.makepyfile(
        test_marked="import pytest\n\npytestmark = pytest.mark.unit\n\n\n"
                    "def test_marked():\n    pass\n",
        test_forgotten="def test_forgotten():\n    pass\n")
    result = pytester.runpytest("-p", "no:cacheprovider", "-p", "no:xdist", *selection)
    result.assert_outcomes(passed=1, errors=1)  # fails in its setup
    result.stdout.fnmatch_lines(["*test_forgotten.py::test_forgotten has no kind marker*"])
