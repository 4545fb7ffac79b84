"""Where frames come from: a camera, a video file, or any function (the simulator's renderer).

Every source has ``read() -> (timestamp_s, frame_bgr) | None`` (None at the end of a stream)
and ``close()``. Frames are BGR, as OpenCV gives them. A source that counts its frames itself
has a ``frame_number``: the number of the frame ``read`` last gave, which changes with every
new picture (the play loop tells a frozen camera by it, and by the pixels where there is none).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np


class FrameSource(Protocol):
    """Where the play loop's frames come from."""

    def read(self) -> tuple[float, np.ndarray] | None:
        """The next frame as (timestamp in seconds, BGR image), or None at the end."""
        ...

    def close(self) -> None: ...


class OpenCVSource:
    """A camera (by index) or a video file (by path), through ``cv2.VideoCapture``.

    Args:
        source: a camera index, or the path of a video file.
        width: the frame width asked of a camera (a file keeps its own).
        height: the frame height asked of a camera.
        fps: the frame rate asked of a camera.
    """

    def __init__(
        self,
        source: int | str,
        width: int | None = None,
        height: int | None = None,
        fps: float | None = None,
    ) -> None:
        if isinstance(source, str) and not source.isdigit() and not Path(source).exists():
            raise FileNotFoundError(f"no video file at {source}")
        self.source = int(source) if isinstance(source, str) and source.isdigit() else source
        self._cap = cv2.VideoCapture(self.source)
        if not self._cap.isOpened():
            raise OSError(f"cannot open camera or video {source!r}")
        for prop, value in (
            (cv2.CAP_PROP_FRAME_WIDTH, width),
            (cv2.CAP_PROP_FRAME_HEIGHT, height),
            (cv2.CAP_PROP_FPS, fps),
        ):
            if value:
                self._cap.set(prop, value)
        self._is_file = isinstance(self.source, str)
        self._fps = self._cap.get(cv2.CAP_PROP_FPS) or 60.0
        self._frames = 0
        # A file's frames are numbered by their place in it (a still scene's are alike); a
        # camera through OpenCV gives no count of its own.
        self.frame_number: int | None = None

    def read(self) -> tuple[float, np.ndarray] | None:
        ok, frame = self._cap.read()
        if not ok:
            return None
        self._frames += 1
        if self._is_file:
            self.frame_number = self._frames
        # A file's frames are timed by its frame rate; a camera's by when they arrive.
        t = self._frames / self._fps if self._is_file else time.monotonic()
        return t, frame

    def close(self) -> None:
        self._cap.release()


class CallableSource:
    """Frames from a function returning RGB images, e.g. ``TableSim.render``.

    Args:
        render: returns an (H, W, 3) uint8 RGB frame, or None when there are no more.
        clock: the frame's timestamp (default: ``time.monotonic``); the simulated table passes
            its simulated time.
    """

    def __init__(
        self, render: Callable[[], np.ndarray], clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.render = render
        self.clock = clock
        # Every call renders afresh: a still scene gives the same pixels, and is no frozen camera.
        self.frame_number = 0

    def read(self) -> tuple[float, np.ndarray] | None:
        t, frame = self.clock(), self.render()
        if frame is None:
            return None
        self.frame_number += 1
        return t, cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)

    def close(self) -> None:
        pass
