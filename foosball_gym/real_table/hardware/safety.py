"""Safety in the driver, not in the policy: limits, rate limits, watchdogs, one stop for all.

No CAN: :mod:`foosball_gym.real_table.hardware.drives` puts it between the play loop and the drives,
and the tests drive it with made-up timestamps.

- :class:`TargetLimiter` turns whatever a policy asks for into targets that stay inside the
  joint limits minus a margin, never move faster than the joint's top speed and change speed no
  faster than its acceleration allows, one control period at a time.
- :class:`Watchdog` trips when the last command or the last state estimate is too old; the
  play loop's own calls check it, and feed the state estimate's side with new camera
  pictures only.
- :class:`CommandGuard` checks the age of the last command from a thread of its own, so a
  loop that hangs (a policy that blocks, a stuck camera read) stops the table within the
  watchdog period instead of at its next call.
- :class:`SafetyLatch` stops every drive once, on the first error from whichever thread, and
  keeps raising that error until the drives are brought up again.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import NoReturn

from foosball_gym.policy_io.target_limits import JointLimits, TargetLimiter
from foosball_gym.real_table.hardware.config import JointConfig

logger = logging.getLogger(__name__)


class SafetyError(RuntimeError):
    """Why the drives must stop. ``TableDrives`` raises it after it stopped every drive."""


class DriveFault(SafetyError):
    """A drive reported or showed a fault.

    Attributes:
        node_id: the drive's node id.
        joint: ``(rod, joint)`` the drive moves.
        reason: what was seen (the statusword's fault bit, an EMCY, a lost heartbeat, ...).
    """

    def __init__(self, joint: JointConfig, reason: str) -> None:
        self.node_id = joint.node_id
        self.joint = joint.key
        self.reason = reason
        super().__init__(f"{joint.label}: {reason}")


class WatchdogTripped(SafetyError):
    """The last command or the last state estimate was older than the watchdog allows.

    Attributes:
        what: ``"command"`` or ``"state estimate"``.
        age: how old it was, in seconds.
        timeout: the watchdog's limit, in seconds.
        why: what the master knows of the cause (a frozen camera), or "".
    """

    def __init__(self, what: str, age: float, timeout: float, why: str = "") -> None:
        self.what = what
        self.age = age
        self.timeout = timeout
        self.why = why
        super().__init__(
            f"watchdog: the last {what} is {age * 1e3:.1f} ms old (limit {timeout * 1e3:.1f} ms)"
            + (f": {why}" if why else "")
        )


__all__ = [
    "CommandGuard",
    "DriveFault",
    "JointLimits",
    "SafetyError",
    "SafetyLatch",
    "TargetLimiter",
    "UnsafeCommand",
    "Watchdog",
    "WatchdogTripped",
]


class UnsafeCommand(SafetyError, ValueError):
    """A command the driver refuses (a target that is not a number, a joint with no drive)."""


class Watchdog:
    """Trips when the last command or the last state estimate is older than ``timeout``.

    The caller passes every timestamp (seconds, any clock, as long as it is one clock), so
    tests and simulated tables can run on their own time. It arms on the first command: a
    bring-up that takes a while does not trip it.

    Args:
        timeout: the oldest a command or a state estimate may be, in seconds.
    """

    def __init__(self, timeout: float) -> None:
        if timeout <= 0:
            raise ValueError(f"the watchdog timeout must be positive, got {timeout}")
        self.timeout = timeout
        self.reset()

    def reset(self) -> None:
        self.last_command: float | None = None
        self.last_state: float | None = None

    @property
    def armed(self) -> bool:
        return self.last_command is not None

    def feed_command(self, now: float) -> None:
        if self.last_command is None and self.last_state is None:
            # Nothing has been estimated yet: the first estimate is due within the timeout.
            self.last_state = now
        self.last_command = now

    def feed_state(self, now: float) -> None:
        self.last_state = now

    def check(self, now: float) -> None:
        """Raise :class:`WatchdogTripped` if armed and something is too old."""
        if self.last_command is None:
            return
        assert self.last_state is not None  # the first command sets it, if nothing had
        for what, last in (("command", self.last_command), ("state estimate", self.last_state)):
            age = now - last
            if age > self.timeout:
                raise WatchdogTripped(what, age, self.timeout)


class CommandGuard:
    """Calls ``on_silence`` from its own thread when no command came for ``timeout`` seconds.

    Armed by the first :meth:`feed` after :meth:`disarm`; it disarms itself when it fires, so
    it fires once per silence.

    Args:
        timeout: the oldest the last command may be, in seconds.
        on_silence: called with the last command's age; what it raises is logged.
        clock: the table's clock, seconds: the wall clock for a real table or one simulated in
            real time, the simulated time in lock-step (where the world waits for the loop).
        poll_s: how often the thread looks; by default a tenth of ``timeout``, 1 to 5 ms.
    """

    def __init__(
        self,
        timeout: float,
        on_silence: Callable[[float], None],
        clock: Callable[[], float] = time.monotonic,
        poll_s: float | None = None,
    ) -> None:
        if timeout <= 0:
            raise ValueError(f"the guard's timeout must be positive, got {timeout}")
        self.timeout = timeout
        self.clock = clock
        self.poll_s = poll_s if poll_s is not None else min(max(timeout / 10, 0.001), 0.005)
        self._on_silence = on_silence
        self._lock = threading.Lock()
        self._last: float | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @property
    def armed(self) -> bool:
        return self._last is not None

    def start(self) -> None:
        """Start the thread (once; a stopped guard stays stopped)."""
        if self._thread is None and not self._stop.is_set():
            self._thread = threading.Thread(target=self._run, name="command-guard", daemon=True)
            self._thread.start()

    def feed(self) -> None:
        """A command went out now."""
        with self._lock:
            self._last = self.clock()

    def disarm(self) -> None:
        with self._lock:
            self._last = None

    def use_clock(self, clock: Callable[[], float]) -> None:
        """Measure on another clock from now on (disarmed until the next command)."""
        with self._lock:
            self.clock = clock
            self._last = None

    def stop(self) -> None:
        """Stop the thread and wait for it; safe to call twice."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()

    def check(self) -> float | None:
        """Fire if the last command is too old; the age it fired at, else None."""
        with self._lock:
            if self._last is None:
                return None
            age = self.clock() - self._last
            if age <= self.timeout:
                return None
            self._last = None
        try:
            self._on_silence(age)
        except Exception:
            logger.exception("the command guard could not stop the table")
        return age

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            self.check()


class SafetyLatch:
    """Stops everything once, on the first safety error, and remembers it.

    Thread-safe: the play loop and the command guard may trip it at the same time; one of
    them stops the drives, and both raise the first error.

    Args:
        stop_all: stops every drive, given the error that calls for it; it should try every
            drive even when one fails, and may raise afterwards to say which failed.
    """

    def __init__(self, stop_all: Callable[[SafetyError], None]) -> None:
        self._stop_all = stop_all
        self._lock = threading.RLock()
        self.error: SafetyError | None = None

    def trip(self, error: SafetyError) -> NoReturn:
        """Stop every drive (the first time) and raise ``error``."""
        with self._lock:
            if self.error is None:
                self.error = error
                try:
                    self._stop_all(error)
                except Exception as e:
                    # The first error is the one to report; a drive that did not take the stop
                    # is part of it.
                    raise error from e
            raise self.error

    def check(self) -> None:
        """Raise the error that tripped the latch, if any, once its stop has been sent (a trip
        on another thread holds the lock until then)."""
        if self.error is not None:
            with self._lock:
                raise self.error

    def reset(self) -> None:
        with self._lock:
            self.error = None
