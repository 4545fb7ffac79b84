"""The simulated table in the PyBullet GUI, in a process of its own: a window to watch the
game in and to play from its keyboard.

PyBullet's GUI answers a client's calls between the frames it draws. With a software renderer (a
virtual display) a physics step then took 14 ms instead of 0.08 ms, a camera frame 53 ms instead of
12 and reading the keyboard 15 ms (measured): a table in the GUI could not keep the wall clock. So
the table that plays stays headless, and a second process holds a copy of it that only poses (as the
camera's does, :mod:`~foosball_gym.real_table.virtual.camera_process`), writes the score and reads
the keyboard. It shows the newest scene it is sent and drops those it has no time for; the keys come
back as they change. The window's own loop never idles: it takes a core or two whatever the table
does.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import threading
from collections.abc import Sequence
from multiprocessing.connection import Connection

# Long enough for a spawned interpreter to import pybullet and open the window.
START_TIMEOUT_S = 60.0
# How long the window waits for a message before it reads the keyboard again (s).
POLL_S = 0.005
# How much lower the window's process runs than the table's.
NICENESS = 10


class WindowError(RuntimeError):
    """The GUI window could not be opened: no display, or one PyBullet cannot reach."""


def _serve(conn: Connection, rods: tuple[str, ...], view_from: str = "top") -> None:
    # The parent ends this process (it sends None, or its end closes the pipe): a Ctrl-C or
    # SIGTERM to the whole process group must reach the parent only, which stops the table
    # and then this.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    # The window gives way to the table, the camera and the loop, which keep the wall clock.
    with contextlib.suppress(OSError, AttributeError):
        os.nice(NICENESS)
    from foosball_gym import table
    from foosball_gym.sim import View

    try:
        view = View([table.rod(name) for name in rods], gui=True, view=view_from)
    except Exception as err:  # the parent raises it, with its message
        conn.send(("error", str(err)))
        return
    still = [0.0] * (2 * len(rods))
    held: frozenset[str] = frozenset()
    try:
        conn.send("ready")
        while True:
            scene = None
            while conn.poll(POLL_S if scene is None else 0):
                message = conn.recv()
                if message is None:
                    return
                kind, *args = message
                if kind == "scene":
                    scene = args  # only the newest is shown
                else:
                    view.show_text(*args)
            if scene is not None:
                positions, ball = scene
                view.pose(positions, still, ball)
                conn.send(("shown",))
            keys, pressed = view.keyboard_events()
            if keys != held or pressed:
                conn.send(("keys", keys, pressed))
                held = keys
    except (EOFError, KeyboardInterrupt, OSError):
        pass  # the parent has gone
    except Exception:
        pass  # the window was closed: PyBullet lost its server, and the parent sees EOF
    finally:
        view.close()


class ViewerProcess:
    """A GUI window on a table with ``rods``, in a separate process, seen from ``view`` (see
    :data:`foosball_gym.sim.view.VIEWS`).

    Raises:
        WindowError: the window could not be opened; the message says why.
    """

    def __init__(self, rods: Sequence[str], view: str = "top") -> None:
        display = os.environ.get("DISPLAY")
        # Spawned, not forked: a forked child would share the parent's PyBullet client.
        context = multiprocessing.get_context("spawn")
        self._conn, child = context.Pipe()
        self._process = context.Process(target=_serve, args=(child, tuple(rods), view), daemon=True)
        self._process.start()
        child.close()
        try:
            answer = self._conn.recv() if self._conn.poll(START_TIMEOUT_S) else None
        except EOFError:
            # PyBullet ends the whole process where it cannot open the window.
            answer = ("error", f"PyBullet could not open its window on the display {display!r}")
        if answer != "ready":
            self.close()
            if isinstance(answer, tuple) and answer[0] == "error":
                raise WindowError(answer[1])
            raise WindowError(f"the GUI window did not open within {START_TIMEOUT_S} s")
        self._send_lock = threading.Lock()
        self._keys_lock = threading.Lock()
        self._drawing = False
        self._held: frozenset[str] = frozenset()
        self._pressed: set[str] = set()
        self._open = True
        self._reader = threading.Thread(target=self._read, name="gui-window", daemon=True)
        self._reader.start()

    @property
    def open(self) -> bool:
        """Whether the window is still there (a person may close it)."""
        return self._open

    def _read(self) -> None:
        try:
            while True:
                message = self._conn.recv()
                if message[0] == "shown":
                    self._drawing = False
                else:
                    _, held, pressed = message
                    with self._keys_lock:
                        self._held = held
                        self._pressed |= pressed
        except (EOFError, OSError):
            self._open = False

    def _send(self, message: object) -> None:
        with self._send_lock, contextlib.suppress(BrokenPipeError, OSError):
            self._conn.send(message)

    def show(self, positions: Sequence[float], ball: Sequence[float]) -> None:
        """Pose the window's table (see :meth:`View.pose`), unless it is still drawing the
        last scene: the window drops what it has no time for."""
        if self._drawing or not self._open:
            return
        self._drawing = True
        self._send(("scene", list(positions), list(ball)))

    def show_text(self, lines: Sequence[str]) -> None:
        """Write ``lines`` in the window (see :meth:`View.show_text`)."""
        self._send(("text", list(lines)))

    def keyboard_events(self) -> tuple[frozenset[str], frozenset[str]]:
        """The keys held in the window now and those pressed since the last call (see
        :meth:`View.keyboard_events`)."""
        with self._keys_lock:
            pressed, self._pressed = frozenset(self._pressed), set()
            return self._held, pressed

    def close(self) -> None:
        """Close the window and stop the process; safe to call twice."""
        if self._process.is_alive():
            with contextlib.suppress(BrokenPipeError, OSError):
                self._conn.send(None)
            self._process.join(timeout=5)
            if self._process.is_alive():
                self._process.kill()
        self._conn.close()
