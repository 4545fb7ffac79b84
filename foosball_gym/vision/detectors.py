"""Finding the ball in a frame: by colour (fast on a CPU) or with an ONNX detection model."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np


@dataclass(frozen=True)
class Detection:
    """A ball found at pixel (u, v) (column, row) with some confidence in [0, 1]."""

    u: float
    v: float
    confidence: float = 1.0


class BallDetector(Protocol):
    def detect(self, frame: np.ndarray) -> Detection | None: ...


class ColourBallDetector:
    """The ball as the largest blob of its colour.

    Args:
        hsv_low, hsv_high: the ball's colour range in OpenCV's HSV (H in 0-179); the defaults
            match the simulator's orange ball.
        min_area_px: smaller blobs are noise.
        max_area_px: larger blobs are not the ball (0: no limit).
    """

    def __init__(
        self,
        hsv_low: tuple[int, int, int] = (5, 120, 120),
        hsv_high: tuple[int, int, int] = (25, 255, 255),
        min_area_px: int = 8,
        max_area_px: int = 0,
    ) -> None:
        self.low = np.array(hsv_low, np.uint8)
        self.high = np.array(hsv_high, np.uint8)
        self.min_area = min_area_px
        self.max_area = max_area_px

    def detect(self, frame: np.ndarray) -> Detection | None:
        mask = cv2.inRange(cv2.cvtColor(frame, cv2.COLOR_BGR2HSV), self.low, self.high)
        n, labels, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        best, best_area = None, self.min_area - 1
        for i in range(1, n):
            area = stats[i, cv2.CC_STAT_AREA]
            if area > best_area and (not self.max_area or area <= self.max_area):
                best, best_area = i, area
        if best is None:
            return None
        # A rod or a figurine in front of the ball can cut it into pieces: take the pieces
        # near the largest, and the circle around them all.
        reach = 3.0 * np.sqrt(best_area / np.pi)
        near = [i for i in range(1, n) if np.hypot(*(centroids[i] - centroids[best])) < reach]
        ys, xs = np.nonzero(np.isin(labels, near))
        (u, v), radius = cv2.minEnclosingCircle(np.column_stack([xs, ys]).astype(np.float32))
        if len(xs) >= 0.8 * np.pi * radius**2:
            u, v = xs.mean(), ys.mean()  # the whole ball is seen: its centroid is more precise
        return Detection(float(u), float(v), 1.0)


def decode_yolo(
    output: np.ndarray, conf_threshold: float = 0.25, class_id: int = 0, layout: str = "auto"
) -> tuple[float, float, float] | None:
    """The best box of ``class_id`` in a YOLO output, as (cx, cy, confidence) in model pixels.

    Args:
        output: the network's output.
        conf_threshold: weaker boxes are ignored.
        class_id: the ball's class.
        layout: ``"v5"``: (1, N, 5 + C) rows of cx, cy, w, h, objectness, class scores;
            ``"v8"``: (1, 4 + C, N) columns of cx, cy, w, h, class scores; ``"auto"``: the
            smaller of the two dimensions holds the box fields (there are always far more
            candidate boxes than fields).
    """
    out = np.asarray(output, dtype=float)
    if out.ndim == 3:
        out = out[0]
    if out.ndim != 2:
        raise ValueError(f"expected a (1, N, 5+C) or (1, 4+C, N) output, got {output.shape}")
    if layout == "auto":
        layout = "v8" if out.shape[0] < out.shape[1] else "v5"
    if layout == "v8":
        boxes = out.T
        scores = boxes[:, 4 + class_id]
    elif layout == "v5":
        boxes = out
        classes = boxes[:, 5:]
        scores = boxes[:, 4] * (classes[:, class_id] if classes.shape[1] else 1.0)
    else:
        raise ValueError(f"unknown YOLO layout {layout!r}; allowed: auto, v5, v8")
    if len(scores) == 0:
        return None
    i = int(np.argmax(scores))
    if scores[i] < conf_threshold:
        return None
    return float(boxes[i, 0]), float(boxes[i, 1]), float(scores[i])


class OnnxBallDetector:
    """A YOLO-style ONNX model run through ``cv2.dnn``; the best box's centre is the ball.

    Args:
        model_path: the .onnx file.
        input_size: the model's square input side (pixels).
        conf_threshold: weaker boxes are ignored.
        class_id: the ball's class.
        layout: the output's layout (see :func:`decode_yolo`).
    """

    def __init__(
        self,
        model_path: str | Path,
        input_size: int = 640,
        conf_threshold: float = 0.25,
        class_id: int = 0,
        layout: str = "auto",
    ) -> None:
        path = Path(model_path)
        if not path.is_file():
            raise FileNotFoundError(f"no ONNX model at {path}")
        try:
            self.net = cv2.dnn.readNetFromONNX(str(path))
        except cv2.error as err:
            raise ValueError(f"cannot read {path} as an ONNX model: {err}") from None
        self.size = input_size
        self.conf_threshold = conf_threshold
        self.class_id = class_id
        self.layout = layout

    def detect(self, frame: np.ndarray) -> Detection | None:
        h, w = frame.shape[:2]
        scale = self.size / max(h, w)
        resized = cv2.resize(frame, (round(w * scale), round(h * scale)))
        # Letterbox: the frame scaled into the square input, padded grey at the bottom/right.
        canvas = np.full((self.size, self.size, 3), 114, np.uint8)
        canvas[: resized.shape[0], : resized.shape[1]] = resized
        blob = cv2.dnn.blobFromImage(canvas, 1 / 255.0, swapRB=True)
        self.net.setInput(blob)
        best = decode_yolo(self.net.forward(), self.conf_threshold, self.class_id, self.layout)
        if best is None:
            return None
        cx, cy, conf = best
        return Detection(cx / scale, cy / scale, conf)
