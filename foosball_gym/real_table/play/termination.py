"""Stopping the table when the process is told to end: SIGTERM (and SIGHUP) met as Ctrl-C is.

Without a handler, SIGTERM ends Python at once: no ``finally`` runs, and the drives are left
to notice the master's silence on their own. With :func:`stop_on_termination`, the signal
raises :class:`Terminated` in the main thread, wherever the loop is (a policy that takes its
time, a camera read), and the way out brakes every drive and switches it off, as for Ctrl-C.
``foosball play`` installs it.

Wherever the loop is, but not half-way into a lock: a signal that lands as the main thread
enters a lock-guarded block in Python's threading code (a queue's ``with self.not_full``)
would leave that lock held for good, and the simulated table's bus and canopen's SDO answers
behind it with it; the drives' stop would then find no drive answering. Such a signal is
taken up again a couple of milliseconds later, once the thread is out of it (at most
:data:`HOLD_LIMIT_S` later).
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

# What a service manager, a closed terminal or ``kill`` sends to end a process.
TERMINATING = (signal.SIGTERM, signal.SIGHUP)
# How soon a signal held out of threading's code is taken up again, and for how long at most.
RETRY_S = 0.002
HOLD_LIMIT_S = 1.0


class Terminated(KeyboardInterrupt):
    """The process was told to end by a signal.

    A ``KeyboardInterrupt``, so that everything on the way out treats it as it treats Ctrl-C:
    every drive is still tried when one fails, and none is left running.

    Attributes:
        signum: the signal's number.
    """

    def __init__(self, signum: int) -> None:
        self.signum = signum
        super().__init__(f"terminated by {signal.Signals(signum).name}")


def catch_termination(signals: tuple[int, ...] = TERMINATING) -> Callable[[], None]:
    """Raise :class:`Terminated` in the main thread on the first of ``signals`` from now on.

    Later ones are ignored, so a second ``kill`` cannot cut the drives' stop short (``kill
    -9`` still ends the process; the drives then stop themselves on the master's lost
    heartbeat). Outside the main thread, where Python cannot handle signals, nothing is
    installed.

    Returns:
        What puts the previous handlers back.
    """
    if threading.current_thread() is not threading.main_thread():
        return lambda: None
    held: dict[str, Any] = {"signum": None, "since": 0.0}

    def handle(signum: int, frame: Any) -> None:
        if signum == signal.SIGALRM:
            signum = held["signum"]
            if signum is None:  # a timer of someone else's: not ours to act on
                return
        elif held["signum"] is None:
            held["signum"], held["since"] = signum, time.monotonic()
        if in_threading_code(frame) and time.monotonic() - held["since"] < HOLD_LIMIT_S:
            signal.setitimer(signal.ITIMER_REAL, RETRY_S)
            return
        for sig in signals:
            signal.signal(sig, signal.SIG_IGN)
        signal.setitimer(signal.ITIMER_REAL, 0)
        held["signum"] = None  # a timer still on its way finds nothing held
        raise Terminated(signum)

    previous = {sig: signal.signal(sig, handle) for sig in (*signals, signal.SIGALRM)}

    def restore() -> None:
        signal.setitimer(signal.ITIMER_REAL, 0)
        for sig, handler in previous.items():
            signal.signal(sig, handler)

    return restore


def in_threading_code(frame: Any) -> bool:
    """Whether ``frame`` runs Python's threading module, where an exception can leave a lock
    acquired with nothing to release it."""
    return frame is not None and frame.f_code.co_filename == threading.__file__


@contextmanager
def stop_on_termination(signals: tuple[int, ...] = TERMINATING) -> Iterator[None]:
    """:func:`catch_termination` while the block runs."""
    restore = catch_termination(signals)
    try:
        yield
    finally:
        restore()
