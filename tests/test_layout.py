"""The package's layout: module-level imports form no cycle, and the core stays small.

The graph is built from the source with :mod:`ast`: every ``import`` and ``from ... import``
at module level (inside ``if``/``try`` blocks too, but not under ``if TYPE_CHECKING:`` and
not inside functions or classes' methods), relative imports resolved; ``from pkg import
name`` is an import of ``pkg.name`` when that is a module, else of ``pkg``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "wuerfel_cvx"

MAX_CORE_MODULES = 58
"""Most modules outside ``wuerfel_cvx.lab`` (``__init__`` files included): 51 since issue 23
merged the modules that were one concept split in two (44 modules and 7 package
``__init__`` files; 63 before); 56 since issue 26 added the ``gradients`` package (its
tape, the QP adjoint, the rigid step's derivatives and the backward pass); 57 since HiGHS
has its adapter (``solve/adapters/highs.py``, one module per solver as for the others:
through cvxpy it failed on resting bodies, ``docs/solver-failures.md``); 58 since the
``velocity`` formulation's step has its derivatives (``gradients/velocity.py``, beside
``gradients/rigid.py``: the corner-space QP and its fit).  A new module
in the core is a decision: raise this number in the same change, or put it in ``lab/``."""


def module_names() -> dict[str, Path]:
    """Every module of the package by dotted name (a package by its own name)."""
    names = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(SRC).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names[".".join(parts)] = path
    return names


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _module_level_imports(body: list[ast.stmt]) -> list[ast.Import | ast.ImportFrom]:
    found: list[ast.Import | ast.ImportFrom] = []
    for node in body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        elif isinstance(node, ast.If):
            if not _is_type_checking(node.test):
                found += _module_level_imports(node.body)
            found += _module_level_imports(node.orelse)
        elif isinstance(node, ast.Try):
            for block in (node.body, node.orelse, node.finalbody,
                          *(handler.body for handler in node.handlers)):
                found += _module_level_imports(block)
        elif isinstance(node, ast.With):
            found += _module_level_imports(node.body)
    return found


def import_graph() -> dict[str, set[str]]:
    """Each module's module-level imports of the package's own modules."""
    modules = module_names()
    graph: dict[str, set[str]] = {}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        targets: set[str] = set()
        for node in _module_level_imports(tree.body):
            if isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
                continue
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                source = ".".join([*base, *([node.module] if node.module else [])])
            else:
                source = node.module or ""
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                targets.add(sub if sub in modules else source)
        deps = {target for target in targets if target in modules and target != name}
        graph[name] = deps
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of nodes (first repeated last), or ``None``."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph.get(node, ())):
            if state.get(dep) == 1:
                return [*stack[stack.index(dep):], dep]
            if dep not in state and (cycle := visit(dep)):
                return cycle
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (cycle := visit(node)):
            return cycle
    return None


def test_the_graph_sees_the_package() -> None:
    graph = import_graph()
    assert "wuerfel_cvx.step.simulation" in graph
    assert "wuerfel_cvx.step.model" in graph["wuerfel_cvx.step.simulation"]


def test_a_cycle_is_found() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycle(graph) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None


def test_module_level_imports_have_no_cycle() -> None:
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_the_core_stays_small() -> None:
    core = [name for name in module_names() if not name.startswith("wuerfel_cvx.lab")]
    assert len(core) <= MAX_CORE_MODULES, (
        f"{len(core)} modules outside wuerfel_cvx.lab (at most {MAX_CORE_MODULES})")


def test_every_package_is_installed() -> None:
    """Every package under ``src`` is listed in pyproject.toml.

    The packages are listed one by one: a new subpackage left out of the list is left out
    of a plain ``pip install .`` (the README's first command then fails).
    """
    import tomllib

    listed = set(tomllib.loads((SRC.parent / "pyproject.toml").read_text())["tool"][
        "setuptools"]["packages"])
    packages = {".".join(init.parent.relative_to(SRC).parts)
                for init in PACKAGE.rglob("__init__.py")}
    assert packages <= listed, sorted(packages - listed)
