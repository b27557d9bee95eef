"""The shape of the package's code: no function over 80 lines.

Lengths are physical lines: a function from its first decorator to its last line (nested
functions count towards the function that holds them, and are checked themselves).
Modules are split by concept, not by size (issue 23), so they have no cap; the package's
layout is checked in ``tests/test_layout.py``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "wuerfel_cvx"
MAX_FUNCTION_LINES = 80


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def function_lengths(path: Path) -> list[tuple[str, int, int]]:
    """``(qualified name, first line, length)`` of every function and method in ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found: list[tuple[str, int, int]] = []

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                first = min([child.lineno, *(d.lineno for d in child.decorator_list)])
                assert child.end_lineno is not None
                found.append((prefix + child.name, first, child.end_lineno - first + 1))
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(tree, "")
    return found


def test_the_package_is_found() -> None:
    assert (PACKAGE / "__init__.py").is_file()
    assert len(_modules()) > 10


def test_function_lengths_are_measured_from_the_first_decorator(tmp_path: Path) -> None:
    source = tmp_path / "sample.py"
    source.write_text("import functools\n\n\n@functools.cache\n@staticmethod\ndef f():\n"
                      "    def g():\n        return 1\n    return g\n\n\nclass C:\n"
                      "    def m(self):\n        pass\n")
    assert function_lengths(source) == [("f", 4, 6), ("f.g", 7, 2), ("C.m", 13, 2)]


def test_no_function_is_over_80_lines() -> None:
    long = [f"{path.relative_to(PACKAGE.parent)}:{line} {name} ({length} lines)"
            for path in _modules() for name, line, length in function_lengths(path)
            if length > MAX_FUNCTION_LINES]
    assert not long, "functions over 80 lines: " + "; ".join(long)

