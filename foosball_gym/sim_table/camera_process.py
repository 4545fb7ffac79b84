"""The simulated table's camera in a process of its own, so that frames come in real time.

PyBullet's CPU renderer needs about 12 ms for a 320 x 180 frame of the table and 46 ms for
640 x 360 (measured on one core): more than the loop can spare in its 16.7 ms period. A
second process holds a copy of the table that only poses and renders. Each control step the
table sends it the new scene; while it renders that one, the loop takes the frame of the step
before. A real camera's frame is as old when the loop gets it: exposure, readout and transfer
take a frame period or more.
"""

from __future__ import annotations

import math
import multiprocessing
import threading
import time
from collections.abc import Sequence
from multiprocessing.connection import Connection

import numpy as np

# Long enough for a spawned interpreter to import pybullet and load the table.
START_TIMEOUT_S = 60.0


def _serve(conn: Connection, rods: tuple[str, ...], width: int, height: int) -> None:
    from foosball_gym.simulator import TableSim

    sim = TableSim(rods)
    try:
        conn.send("ready")
        while True:
            request = conn.recv()
            if request is None:
                break
            stamp, positions, ball = request
            sim.show(positions, ball)
            conn.send((stamp, sim.render(width, height)))
    except (EOFError, KeyboardInterrupt, BrokenPipeError):
        pass
    finally:
        sim.close()


class CameraProcess:
    """Renders scenes of a table with ``rods`` in a separate process, one at a time.

    :meth:`request` hands over a scene without waiting; :meth:`latest` gives the newest frame
    rendered so far, waiting only when none has come since the last call. Scenes are stamped
    ``(serve, t)``: the serve they belong to and their time, so that a frame taken just before
    a serve is told from one taken just after it at the same time.
    """

    def __init__(self, rods: Sequence[str], width: int, height: int) -> None:
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
        self._pending = 0
        self._frame: tuple[tuple[int, float], np.ndarray] | None = None
        self._fresh = False

    def request(
        self,
        stamp: tuple[int, float],
        positions: Sequence[float],
        ball: Sequence[float],
        *,
        queue: bool = False,
    ) -> None:
        """Start rendering a scene, unless the last one is still being rendered (a camera
        drops frames it has no time for); ``queue`` renders it after that one instead."""
        with self._lock:
            self._collect(block=False)
            if self._pending and not queue:
                return
            self._conn.send((stamp, list(positions), list(ball)))
            self._pending += 1

    def latest(
        self, after: tuple[int, float] = (0, -math.inf), timeout: float = 1.0
    ) -> tuple[tuple[int, float], np.ndarray]:
        """The newest frame and its scene's stamp, waiting for one stamped ``after`` or later,
        and for a new one when none has come since the last call."""
        deadline = time.monotonic() + timeout
        while True:
            with self._lock:
                self._collect(block=False)
                if not self._fresh and self._pending:
                    self._collect(block=True, timeout=max(deadline - time.monotonic(), 0.0))
                if self._frame is not None and self._frame[0] >= after:
                    self._fresh = False
                    return self._frame
            if time.monotonic() > deadline:
                raise RuntimeError(f"the camera process sent no frame within {timeout} s")
            # The scene asked for is not requested yet: the table's next step will.
            time.sleep(0.001)

    def _collect(self, block: bool, timeout: float = 1.0) -> None:
        while self._pending and (self._conn.poll(timeout if block else 0)):
            self._frame = self._conn.recv()
            self._pending -= 1
            self._fresh = True
            block = False
        if block and not self._fresh:
            raise RuntimeError(f"the camera process sent no frame within {timeout} s")

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
