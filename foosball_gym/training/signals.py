"""Stopping a training run cleanly on Ctrl-C or SIGTERM, for either backend."""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


class SignalStop:
    """Records SIGINT or SIGTERM while :meth:`installed`; the trainer stops at its next step.

    Stopping between steps, not where the signal lands, leaves no update half done, so the
    checkpoint written afterwards holds a consistent model. A second signal stops at once.
    """

    signum: int | None = None

    def _handle(self, signum: int, frame: Any) -> None:
        if self.signum is not None:
            raise KeyboardInterrupt
        self.signum = signum

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
