"""Exceptions of the package.

Every error a user can cause by bad input is an :class:`InputError`: the command
line prints it as one line and exits with status 2.  A solver that fails on a step
raises :class:`StepFailure`, which carries the step, solver and status and the
trajectory computed so far.  Ctrl-C during a run raises :class:`Interrupted`, which is a
:class:`KeyboardInterrupt`, not an error.
"""

from __future__ import annotations

from typing import Any


class WuerfelError(Exception):
    """Base class of every error raised on purpose by ``wuerfel_cvx``."""


class InputError(WuerfelError, ValueError):
    """Bad input: a scene file, a field in it, or an option.

    Parameters
    ----------
    message:
        What is wrong, in one line.
    source:
        The file (or named scene) the input came from, if any.
    field:
        The dotted field path inside the source, e.g. ``squares[2].mass``.

    """

    def __init__(self, message: str, *, source: str | None = None, field: str | None = None):
        self.source = source
        self.field = field
        self.reason = message
        where = ": ".join(part for part in (source, field) if part)
        super().__init__(f"{where}: {message}" if where else message)


class StepFailure(WuerfelError, RuntimeError):
    """A solver did not return a usable solution for one time step.

    Attributes
    ----------
    step:
        The 1-based index of the step that failed (step ``k`` goes from time
        ``(k-1) dt`` to ``k dt``).
    solver:
        The solver's registry name.
    status:
        The solver's status string, or a description of the failed check.
    trajectory:
        The trajectory up to the last good step (set by :func:`wuerfel_cvx.simulate`).

    """

    def __init__(self, step: int, solver: str, status: str, detail: str = ""):
        self.step = step
        self.solver = solver
        self.status = status
        self.detail = detail
        self.trajectory: Any = None
        text = f"step {step}: solver {solver} failed with status '{status}'"
        super().__init__(f"{text} ({detail})" if detail else text)


class Interrupted(KeyboardInterrupt):
    """A run stopped by the user (Ctrl-C); it keeps what was computed before.

    A :class:`KeyboardInterrupt` and deliberately not an :class:`Exception` (nor a
    :class:`WuerfelError`): code that turns any exception into a result, such as a
    benchmark's error row or a robustness finding, lets a Ctrl-C through, and code that
    does not know it stops as before.

    Attributes
    ----------
    step:
        The 1-based index of the step that was interrupted, one more than the steps in
        ``trajectory`` (it is not part of it).
    trajectory:
        The trajectory up to the last completed step.

    """

    def __init__(self, step: int):
        self.step = step
        self.trajectory: Any = None
        super().__init__(f"interrupted during step {step}")
