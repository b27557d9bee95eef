"""wuerfel_cvx: squares and boxes falling and stacking in 2-D, one convex QP per time step.

    >>> from wuerfel_cvx import Scene, simulate
    >>> traj = simulate(Scene.named("tilted-drop"), dt=0.01, steps=200)

Each square or box is 4 corner masses joined by 5 rods (the seed paper "Fallende Wuerfel");
each step minimises ``sum m_i |a_i - g|^2`` (or its velocity form) under rod equalities
and point-versus-edge inequalities, declared in CVXPY and solved by a chosen solver.

The public names are imported on first use (PEP 562), so that ``import wuerfel_cvx.<x>``
costs no cvxpy import until it is needed: the command line (:mod:`wuerfel_cvx.__main__`)
starts taking Ctrl-C before it imports anything heavy.
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

from .errors import InputError, Interrupted, StepFailure, WuerfelError

if TYPE_CHECKING:
    from .scenes.scene import Box, Scene, Square, Table
    from .settings import Settings
    from .simulate import simulate
    from .solve.registry import available_solvers
    from .step.simulation import Simulation
    from .trajectory import Trajectory

__version__ = "0.1.0"

__all__ = ["Box", "InputError", "Interrupted", "Scene", "Settings", "Simulation", "Square",
           "StepFailure", "Table", "Trajectory", "WuerfelError", "available_solvers", "simulate"]

_LAZY = {"Box": "scenes.scene", "Scene": "scenes.scene", "Square": "scenes.scene",
         "Table": "scenes.scene", "Settings": "settings", "simulate": "simulate",
         "Simulation": "step.simulation", "available_solvers": "solve.registry",
         "Trajectory": "trajectory"}
"""Each public name imported on first use, and its module."""


def _lazy_names(package: str, modules: Mapping[str, str], public: Sequence[str],
                ) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package``, whose ``modules`` map names to modules.

    Public names of a package imported on first use (PEP 562): a package whose public
    names live in heavy modules (cvxpy, the solvers) declares them in a table and takes its
    module-level ``__getattr__`` and ``__dir__`` from here (this package and
    :mod:`wuerfel_cvx.solve`).  Importing the package then imports none of them, and the
    first use of a name imports its module and keeps the name.  ``modules`` maps each
    lazily imported name to its module relative to ``package``; ``public`` is the
    package's ``__all__``.
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


__getattr__, __dir__ = _lazy_names(__name__, _LAZY, __all__)


class _Package(types.ModuleType):
    """The package's type: its ``simulate`` stays the function when the module is imported.

    Importing the module ``wuerfel_cvx.simulate`` sets the package's attribute of that name
    to the module; the function of the same name is the public one (as it was when this
    file imported it eagerly).
    """

    def __setattr__(self, name: str, value: Any) -> None:
        if name == "simulate" and isinstance(value, types.ModuleType):
            value = value.simulate
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
