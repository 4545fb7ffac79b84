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

    The frame is thresholded in HSV and closed (which fills the highlight a real ball shows);
    the largest blob in the area range is the ball, and its centre is the centroid of its
    pixels. Pieces of the ball that a rod or a figurine cuts off are taken with it. Where a rod
    or a figurine hides part of the ball, the centroid of what is left moves away from it: then
    a circle is fitted to the ball's own outline, without the edges the hiding part cuts across
    it (they lie inside the circle), and its centre is used instead. The detection's confidence
    is the share of the smallest circle around the pieces that the ball's pixels fill (1: seen
    whole).
    To stay fast at high frame rates, a window around where the last detections put the ball
    is searched first, and the whole frame only when the ball is not found there.

    Args:
        hsv_low: the low end of the ball's colour range in OpenCV's HSV (H in 0-179); the
            defaults match the simulator's orange ball (and exclude the shaded brown walls).
        hsv_high: the high end of that range.
        min_area_px: smaller blobs are noise.
        max_area_px: larger blobs are not the ball (0: no limit).
        roi_px: half the side of the window searched first (0: always the whole frame).
        close_px: side of the closing's square kernel (0 or 1: no closing).
    """

    def __init__(
        self,
        hsv_low: tuple[int, int, int] = (5, 120, 120),
        hsv_high: tuple[int, int, int] = (25, 255, 255),
        min_area_px: int = 8,
        max_area_px: int = 0,
        roi_px: int = 48,
        close_px: int = 3,
    ) -> None:
        self.low = np.array(hsv_low, np.uint8)
        self.high = np.array(hsv_high, np.uint8)
        self.min_area = min_area_px
        self.max_area = max_area_px
        self.roi_px = roi_px
        self._kernel = np.ones((close_px, close_px), np.uint8) if close_px > 1 else None
        self._track: list[Detection] = []  # the last two detections, newest last

    def detect(self, frame: np.ndarray) -> Detection | None:
        found = None
        if self._track and self.roi_px > 0:
            # Where the ball would be if it kept the last frame's displacement.
            last = self._track[-1]
            u, v = last.u, last.v
            if len(self._track) == 2:
                u, v = 2 * u - self._track[0].u, 2 * v - self._track[0].v
            h, w = frame.shape[:2]
            u0, v0 = max(int(u) - self.roi_px, 0), max(int(v) - self.roi_px, 0)
            u1, v1 = min(int(u) + self.roi_px + 1, w), min(int(v) + self.roi_px + 1, h)
            if u0 < u1 and v0 < v1:
                found = self._find(frame[v0:v1, u0:u1], (u0, v0), inside=True)
        if found is None:
            found = self._find(frame, (0, 0), inside=False)
        self._track = [*self._track[-1:], found] if found is not None else []
        return found

    def _find(self, image: np.ndarray, origin: tuple[int, int], inside: bool) -> Detection | None:
        """The ball in ``image`` (a window of the frame starting at ``origin``).

        With ``inside``, a ball touching the window's border is not taken: part of it may lie
        outside.
        """
        mask = cv2.inRange(cv2.cvtColor(image, cv2.COLOR_BGR2HSV), self.low, self.high)
        if self._kernel is not None:
            mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, self._kernel)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
        best, best_area = None, 0.0
        for contour in contours:
            area = cv2.contourArea(contour)
            too_big = self.max_area and area > self.max_area
            if area >= self.min_area and area > best_area and not too_big:
                best, best_area = contour, area
        if best is None:
            return None
        # A rod or a figurine in front of the ball can cut it into pieces: take the pieces
        # near the largest, and the circle around them all.
        (bu, bv), _ = cv2.minEnclosingCircle(best)
        reach = 3.0 * np.sqrt(best_area / np.pi)
        pieces = [
            c for c in contours if np.hypot(*(c.reshape(-1, 2).mean(axis=0) - (bu, bv))) < reach
        ]
        outline = np.vstack(pieces)
        x, y, w, h = cv2.boundingRect(outline)
        if inside and (x == 0 or y == 0 or x + w == mask.shape[1] or y + h == mask.shape[0]):
            return None
        (u, v), radius = cv2.minEnclosingCircle(outline)
        moments = cv2.moments(mask[y : y + h, x : x + w], binaryImage=True)
        count = moments["m00"]
        fill = count / (np.pi * max(radius, 0.5) ** 2)
        arc = _outline_circle(outline.reshape(-1, 2).astype(float))
        if arc is not None:  # partly hidden: the circle of its own outline
            u, v = arc
        elif fill >= 0.8:  # the whole ball is seen: its centroid is more precise
            u, v = x + moments["m10"] / count, y + moments["m01"] / count
        return Detection(float(u + origin[0]), float(v + origin[1]), float(min(fill, 1.0)))


# An outline point this far (px) inside the circle fitted to the outline lies on an edge that
# something in front of the ball cuts across it, not on the ball's rim; and a ball is taken as
# partly hidden when at least this share of its outline lies on such edges. (A whole ball's rim
# lies within 1 px of its circle: 299 of 300 rendered whole balls lost under 5 % to the cut.)
_CUT_PX = 1.0
_HIDDEN_SHARE = 0.05


def _fit_circle(points: np.ndarray) -> tuple[float, float, float]:
    """The least-squares circle through ``points`` (N x 2): centre and radius."""
    x, y = points[:, 0], points[:, 1]
    lhs = np.column_stack([2 * x, 2 * y, np.ones(len(x))])
    (cu, cv, c), *_ = np.linalg.lstsq(lhs, x * x + y * y, rcond=None)
    return float(cu), float(cv), float(np.sqrt(max(c + cu * cu + cv * cv, 0.0)))


def _outline_circle(points: np.ndarray) -> tuple[float, float] | None:
    """The centre of the circle of a ball's own outline, or None where the outline is the
    whole rim (nothing hides part of the ball).

    The edges that something in front of the ball cuts across it lie inside the ball's circle,
    so a circle fitted to all of the outline leaves them inside it; they are left out and the
    circle fitted again, until the points kept do not change.
    """
    if len(points) < 8:
        return None
    keep = np.ones(len(points), bool)
    for _ in range(4):
        cu, cv, r = _fit_circle(points[keep])
        inside = np.hypot(points[:, 0] - cu, points[:, 1] - cv) - r < -_CUT_PX
        if (keep == ~inside).all():
            break
        keep = ~inside
        if keep.sum() < 5:
            return None
    if keep.mean() > 1 - _HIDDEN_SHARE:
        return None
    return cu, cv


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
