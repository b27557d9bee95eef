"""Public names of a package imported on first use (PEP 562), for its ``__init__``.

A package whose public names live in heavy modules (cvxpy, the solvers) declares them in a
table and takes its module-level ``__getattr__`` and ``__dir__`` from :func:`lazy_names`:
importing the package then imports none of them, and the first use of a name imports its
module and keeps the name.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping, Sequence
from typing import Any


def lazy_names(package: str, modules: Mapping[str, str], public: Sequence[str],
               ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package``, whose ``modules`` map names to modules.

    ``modules`` maps each lazily imported name to its module relative to ``package``;
    ``public`` is the package's ``__all__``.
    """

    def getattr_(name: str) -> Any:
        module = modules.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def dir_() -> list[str]:
        return sorted({*vars(sys.modules[package]), *public})

    return getattr_, dir_
