"""Stopping a training run cleanly on Ctrl-C or SIGTERM, for either backend."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


class Interrupted(Exception):
    """A signal arrived during work that stops where it lands (:meth:`SignalStop.interruptible`)."""


class SignalStop:
    """Records SIGINT or SIGTERM while :meth:`installed`; the trainer stops at its next step.

    Stopping between steps, not where the signal lands, leaves no update half done, so the
    checkpoint written afterwards holds a consistent model. A second signal stops at once.
    Work that changes nothing of the run, an evaluation, runs :meth:`interruptible`: a
    signal stops it where it lands, not after its last game.
    """

    signum: int | None = None
    _at_once: bool = False

    def _handle(self, signum: int, frame: Any) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum
        if self._at_once:
            raise Interrupted(signum)

    @contextmanager
    def interruptible(self) -> Iterator[None]:
        """Run the block to its end unless a signal arrives (or has arrived): then it stops
        at once with :class:`Interrupted`, as Python's own Ctrl-C stops code, so the
        block must hold nothing that a stop half-way would leave wrong (it evaluates; the
        caller writes what it found afterwards)."""
        if self.signum is not None:
            raise Interrupted(self.signum)
        self._at_once = True
        try:
            yield
        finally:
            self._at_once = False

    @contextmanager
    def installed(self) -> Iterator[None]:
        """Catch SIGINT and SIGTERM meanwhile (only the main thread may; elsewhere: nothing)."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {
            sig: signal.signal(sig, self._handle) for sig in (signal.SIGINT, signal.SIGTERM)
        }
        try:
            yield
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
