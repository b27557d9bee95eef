"""Ctrl-C in a sweep: held back while processes or a cluster start or stop.

A sweep stops on the first Ctrl-C (:class:`KeyboardInterrupt` in the main thread), keeping
the rows written so far.  What it has started must then be ended whole: a Dask cluster cut
short while it starts cannot be closed cleanly (a traceback at exit, workers left), and a
second Ctrl-C while the workers are being stopped would leave some running.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

from ...__main__ import relayed_presses


@contextmanager
def held_ctrl_c() -> Iterator[threading.Event]:
    """Hold back Ctrl-C within the block; the event says whether it was pressed.

    In the main thread only (elsewhere no signal arrives); the handler in place before is
    put back afterwards, and the caller decides what a press means.  Under the command
    line's relay (:mod:`wuerfel_cvx.__main__`) Ctrl-C is ignored within the block, and the
    relay counts the presses: a process started within (a Dask worker) inherits the
    ignoring from its first instruction.  Without it, a press is noted by a handler, and
    the event is set as it comes.
    """
    pressed = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield pressed
        return
    before = relayed_presses()

    def note(signum: int, frame: FrameType | None) -> None:
        pressed.set()

    previous = signal.signal(signal.SIGINT, note if before is None else signal.SIG_IGN)
    try:
        yield pressed
    finally:
        signal.signal(signal.SIGINT, previous)
        if before is not None and relayed_presses() != before:
            pressed.set()


def ignore_ctrl_c() -> None:
    """Ignore Ctrl-C in this process: the initializer of a sweep's worker processes.

    The process that runs the sweep takes the Ctrl-C (a terminal sends it to every process
    of the command) and stops its workers itself.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
