"""Stopping the table when the process is told to end: SIGTERM (and SIGHUP) met as Ctrl-C is.

Without a handler, SIGTERM ends Python at once: no ``finally`` runs, and the drives are left
to notice the master's silence on their own. With :func:`stop_on_termination`, the signal
raises :class:`Terminated` in the main thread, wherever the loop is (a policy that takes its
time, a camera read), and the way out brakes every drive and switches it off, as for Ctrl-C.
``foosball play`` installs it.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

# What a service manager, a closed terminal or ``kill`` sends to end a process.
TERMINATING = (signal.SIGTERM, signal.SIGHUP)


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

    def handle(signum: int, frame: Any) -> None:
        for sig in signals:
            signal.signal(sig, signal.SIG_IGN)
        raise Terminated(signum)

    previous = {sig: signal.signal(sig, handle) for sig in signals}

    def restore() -> None:
        for sig, handler in previous.items():
            signal.signal(sig, handler)

    return restore


@contextmanager
def stop_on_termination(signals: tuple[int, ...] = TERMINATING) -> Iterator[None]:
    """:func:`catch_termination` while the block runs."""
    restore = catch_termination(signals)
    try:
        yield
    finally:
        restore()
