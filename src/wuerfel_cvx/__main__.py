"""The process entry of ``wuerfel-cvx`` and ``python -m wuerfel_cvx``: Ctrl-C from the start.

Two things happen here before anything heavy is imported (cvxpy takes seconds):

- A Ctrl-C during start-up ends with one line and exit status 130, not a traceback.
- SIGINT is blocked in every thread and taken by one relay thread, which hands it to the
  main thread as Python's own Ctrl-C (:func:`_thread.interrupt_main`): a
  :class:`KeyboardInterrupt` at the main thread's next bytecode.  A solver library that
  installs its own SIGINT handler while it iterates (OSQP and SCS do) would otherwise take
  the Ctrl-C and return a failed status, and the run would end as a solver failure; now
  the solve finishes and the run stops as interrupted.  Threads and processes started
  later inherit the blocked signal: the workers of a sweep leave Ctrl-C to this process,
  which stops them (:mod:`wuerfel_cvx.lab.bench.sweep`).

The commands themselves are in :mod:`wuerfel_cvx.cli`.  Run as ``python -m wuerfel_cvx``,
this module registers itself under its own name, ``wuerfel_cvx.__main__``, before it starts:
the modules that import it later (:mod:`wuerfel_cvx.cli` for :data:`PROG`,
:mod:`wuerfel_cvx.lab.bench.ctrl_c` for :func:`relayed_presses`) then find this module and
its relay's state, not a second copy.
"""

from __future__ import annotations

import _thread
import signal
import sys
import threading
from collections.abc import Sequence

PROG = "wuerfel-cvx"
INTERRUPTED = 130
"""Exit status of a run stopped by Ctrl-C (128 + SIGINT, as shells report it)."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with Ctrl-C relayed (see the module's docstring); exit status.

    For a process of its own: it leaves SIGINT blocked and then ignored.
    """
    try:
        relay_ctrl_c()
        from .cli import main as run

        return run(argv)
    except KeyboardInterrupt:  # during start-up, or a second Ctrl-C while stopping
        print(f"{PROG}: interrupted", file=sys.stderr)
        return INTERRUPTED
    finally:  # the interpreter's shutdown is not to be interrupted into a traceback
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)


def relay_ctrl_c() -> bool:
    """Block SIGINT in this thread (and all it starts) and relay it to the main thread.

    Does nothing, and returns False, outside the main thread, where signals cannot be
    relayed, if SIGINT is ignored (a background job), or where the platform has no
    ``pthread_sigmask`` (Windows).
    """
    if (threading.current_thread() is not threading.main_thread()
            or not hasattr(signal, "pthread_sigmask")
            or signal.getsignal(signal.SIGINT) is signal.SIG_IGN):
        return False
    global _relaying
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    _relaying = True
    threading.Thread(target=_relay, name="ctrl-c relay", daemon=True).start()
    return True


def relayed_presses() -> int | None:
    """How many Ctrl-C the relay has taken so far; ``None`` without a relay.

    Counted even while Ctrl-C is ignored: :func:`wuerfel_cvx.lab.bench.ctrl_c.held_ctrl_c`
    ignores it while the processes of a Dask cluster start (so that they inherit the
    ignoring) and still learns that it was pressed.
    """
    return _presses if _relaying else None


_relaying = False
_presses = 0


def _relay() -> None:
    """Wait for SIGINT and raise it in the main thread, as often as it comes."""
    global _presses
    while True:
        signal.sigwait({signal.SIGINT})
        _presses += 1
        _thread.interrupt_main(signal.SIGINT)


if __name__ == "__main__":
    sys.modules.setdefault(f"{__package__}.__main__", sys.modules[__name__])
    sys.exit(main())
