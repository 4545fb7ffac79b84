"""The simulated table's camera in a process of its own, so that frames come in real time.

PyBullet's CPU renderer needs about 3 ms for a 320 x 180 frame of one rod and 5 ms for all
eight (the field and walls drawn once, see ``View.render``; measured on one core), time
the loop's own core cannot spare on top of its work, and a shared machine sometimes holds a
render up for tens of milliseconds. A second process holds a copy of the table that only
poses and renders. Each control step the table sends it the new scene, and the loop takes
the newest frame whose latency has passed: a real camera's frame is some 30 ms old when the
loop gets it (exposure, readout and transfer).
"""

from __future__ import annotations

import collections
import math
import multiprocessing
import signal
import threading
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection

import numpy as np

# Long enough for a spawned interpreter to import pybullet and load the table.
START_TIMEOUT_S = 60.0
# How long a closed pipe waits for the process's exit code before calling it still there.
GONE_WAIT_S = 1.0


def _serve(conn: Connection, rods: tuple[str, ...], width: int, height: int) -> None:
    # The parent ends this process (it sends None, or its end closes the pipe): a Ctrl-C or
    # SIGTERM to the whole process group must reach the parent only, which stops the table
    # and then this.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    from foosball_gym import table
    from foosball_gym.sim import View

    view = View([table.rod(name) for name in rods], gui=False)
    still = [0.0] * (2 * len(rods))
    try:
        # The first picture draws the table's fixed parts; drawn before the loop asks for one.
        view.render(width, height)
        conn.send("ready")
        while True:
            request = conn.recv()
            if request is None:
                break
            stamp, positions, ball = request
            view.pose(positions, still, ball)
            conn.send((stamp, view.render(width, height)))
    except (EOFError, KeyboardInterrupt, BrokenPipeError):
        pass
    finally:
        view.close()


Stamp = tuple[int, float]
Frame = tuple[Stamp, np.ndarray]
# Frames kept beyond those a camera's latency holds back: a few control periods' worth.
KEPT_FRAMES = 8


class FrameBuffer:
    """The last frames a camera took, and which of them a loop has been given.

    :meth:`give` hands out the newest frame stamped between ``after`` and ``upto`` (a frame
    is usable once its latency has passed), each frame once: asked again with nothing newer,
    it says so with ``(stamp, None)``, the stamp of the last frame given.
    """

    def __init__(self, kept: int = KEPT_FRAMES) -> None:
        self.frames: collections.deque[Frame] = collections.deque(maxlen=kept)
        self.given: Stamp | None = None

    def add(self, frame: Frame) -> None:
        self.frames.append(frame)

    def new(self, stamp: Stamp) -> bool:
        """Whether a frame stamped ``stamp`` would be news to the loop."""
        return self.given is None or stamp > self.given

    def newest(self, after: Stamp, upto: tuple[float, float]) -> Frame | None:
        for frame in reversed(self.frames):
            if after <= frame[0] <= upto:
                return frame
        return None

    def give(
        self, after: Stamp, upto: tuple[float, float]
    ) -> tuple[Stamp, np.ndarray | None] | None:
        """The newest usable frame not given yet; ``(last stamp given, None)`` when there is
        none but one was given since ``after``; None when none was."""
        frame = self.newest(after, upto)
        if frame is not None and self.new(frame[0]):
            self.given = frame[0]
            return frame
        if self.given is not None and self.given >= after:
            return self.given, None
        return None


class CameraGone(OSError):
    """The camera process ended while the table ran (killed, or crashed)."""


class CameraProcess:
    """Renders scenes of a table with ``rods`` in a separate process, one at a time.

    :meth:`request` hands over a scene without waiting; :meth:`latest` gives the newest frame
    rendered so far that may be used, waiting only for one being rendered. Scenes are
    stamped ``(serve, t)``: the serve they belong to and their time, so that a frame taken
    just before a serve is told from one taken just after it at the same time.
    """

    def __init__(
        self, rods: Sequence[str], width: int, height: int, kept: int = KEPT_FRAMES
    ) -> None:
        # Spawned, not forked: a forked child would share the parent's PyBullet client.
        context = multiprocessing.get_context("spawn")
        self._conn, child = context.Pipe()
        self._process = context.Process(
            target=_serve, args=(child, tuple(rods), width, height), daemon=True
        )
        self._process.start()
        child.close()
        if not self._conn.poll(START_TIMEOUT_S) or self._conn.recv() != "ready":
            self.close()
            raise RuntimeError(f"the camera process did not start within {START_TIMEOUT_S} s")
        self._lock = threading.Lock()
        self._requested: collections.deque[Stamp] = collections.deque()
        self._buffer = FrameBuffer(kept)

    @property
    def given(self) -> Stamp | None:
        """The stamp of the last frame :meth:`latest` gave."""
        return self._buffer.given

    def request(
        self,
        stamp: Stamp,
        positions: Sequence[float],
        ball: Sequence[float],
        *,
        queue: bool = False,
    ) -> None:
        """Start rendering a scene, unless the last one is still being rendered (a camera
        drops frames it has no time for); ``queue`` renders it after that one instead."""
        with self._lock:
            self._collect(block=False)
            if self._requested and not queue:
                return
            try:
                self._conn.send((stamp, list(positions), list(ball)))
            except (BrokenPipeError, OSError):
                raise self._gone() from None
            self._requested.append(stamp)

    def latest(
        self,
        after: Stamp = (0, -math.inf),
        upto: tuple[float, float] = (math.inf, math.inf),  # no bound
        timeout: float = 1.0,
        patience: float | None = None,
    ) -> tuple[Stamp, np.ndarray | None]:
        """The newest frame stamped between ``after`` and ``upto`` not given before, waiting
        for one being rendered, and for one stamped ``after`` or later if none has come.

        ``(stamp, None)`` says there is no new frame to use: the one of ``stamp`` is still
        being rendered after ``patience`` (s), or none newer than the last frame given, of
        ``stamp``, is due. A shared machine sometimes holds the renderer up for tens of
        milliseconds, and a loop that waited for it would go a watchdog period without a
        command.
        """
        now = time.monotonic()
        deadline = now + timeout
        give_up = min(deadline, now + patience) if patience is not None else deadline
        buffer = self._buffer
        while True:
            with self._lock:
                self._collect(block=False)
                newest = buffer.newest(after, upto)
                coming = [
                    s
                    for s in self._requested
                    if after <= s <= upto and buffer.new(s) and (newest is None or s > newest[0])
                ]
                if coming:
                    wait = give_up - time.monotonic()
                    if wait > 0:
                        self._collect(block=True, timeout=wait)
                        continue
                    # Too late: an older frame not given yet still serves, else none does.
                    given = buffer.give(after, upto)
                    if given is not None and given[1] is not None:
                        return given
                    return coming[-1], None
                given = buffer.give(after, upto)
                if given is not None:
                    return given
            if time.monotonic() > deadline:
                raise RuntimeError(f"the camera process sent no frame within {timeout} s")
            # The scene asked for is not requested yet: the table's next step will.
            time.sleep(0.001)

    def _collect(self, block: bool, timeout: float = 0.0) -> None:
        try:
            while self._requested and self._conn.poll(timeout if block else 0):
                self._buffer.add(self._conn.recv())
                self._requested.popleft()
                block = False
        except (EOFError, OSError):
            raise self._gone() from None

    def _gone(self) -> CameraGone:
        # The table's clock thread and the loop can both meet the closed pipe and wait for the
        # process at once; the one whose wait the kernel does not answer sees no exit code until
        # the other has stored it, a moment later (a killed process was once reported as still
        # there).
        deadline = time.monotonic() + GONE_WAIT_S
        code = None
        while code is None and time.monotonic() < deadline:
            self._process.join(timeout=0.01)
            code = self._process.exitcode
        how = (
            "is still there but its pipe is closed"
            if code is None
            else f"was killed by {signal.Signals(-code).name}"
            if code < 0
            else f"exited with status {code}"
        )
        return CameraGone(f"the simulated table's camera process {how}: the table was stopped")

    def close(self) -> None:
        """Stop the process; safe to call twice."""
        if self._process.is_alive():
            try:
                self._conn.send(None)
            except (BrokenPipeError, OSError):
                pass
            self._process.join(timeout=5)
            if self._process.is_alive():
                self._process.kill()
        self._conn.close()
