"""The simulated camera above the table, as a pinhole model, and how a camera errs (no
simulator needed)."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

# The largest image side (pixels) the simulator renders: 4K. A 4096 x 4096 frame of the full
# table takes the process to 1.2 GB; a side of 10**6 crashed it.
MAX_IMAGE_SIDE = 4096


def check_image_side(name: str, value: Any) -> int:
    """An image side in pixels, or a ValueError unless it is a whole number in
    [1, MAX_IMAGE_SIDE]."""
    if (
        not isinstance(value, (int, np.integer))
        or isinstance(value, bool)
        or not 1 <= value <= MAX_IMAGE_SIDE
    ):
        raise ValueError(
            f"{name} must be a whole number of pixels in [1, {MAX_IMAGE_SIDE}], got {value!r}"
        )
    return int(value)


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera straight above the table centre, as the simulator renders it.

    It looks down at the origin with the image's up direction along +y, so +x is to the right
    of the image. Pixel coordinates are OpenCV's (column, row; pixel centres at integers).

    Attributes:
        width, height: image size in pixels.
        height_above_table: the camera's height above the playing surface (m).
        horizontal_half_extent: metres of table visible either side of x = 0, at the surface.
    """

    width: int
    height: int
    height_above_table: float = 1.0
    horizontal_half_extent: float = 0.75

    @property
    def vertical_fov_deg(self) -> float:
        half_h = self.horizontal_half_extent * self.height / self.width
        return math.degrees(2 * math.atan(half_h / self.height_above_table))

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (square pixels)."""
        return self.width / 2 / (self.horizontal_half_extent / self.height_above_table)

    @property
    def principal_point(self) -> tuple[float, float]:
        # Measured on PyBullet's renderer: the optical axis lands one row above the image's
        # middle (at 320x180, 640x360 and 1280x720 alike).
        return self.width / 2, self.height / 2 - 1

    def intrinsics(self) -> np.ndarray:
        f = self.focal_px
        cx, cy = self.principal_point
        return np.array([[f, 0, cx], [0, f, cy], [0, 0, 1]], dtype=float)

    def rotation(self) -> np.ndarray:
        """World to camera rotation (OpenCV camera axes: x right, y down, z forward)."""
        return np.diag([1.0, -1.0, -1.0])

    def translation(self) -> np.ndarray:
        """World to camera translation: the world origin in camera coordinates."""
        return np.array([0.0, 0.0, self.height_above_table])

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) to pixel coordinates (N, 2): column, row."""
        points = np.atleast_2d(points)
        depth = self.height_above_table - points[:, 2]
        f = self.focal_px
        cx, cy = self.principal_point
        u = cx + f * points[:, 0] / depth
        v = cy - f * points[:, 1] / depth
        return np.stack([u, v], axis=1)


@dataclass(frozen=True)
class CameraNoise:
    """How the simulated camera and detector err.

    Attributes:
        fps: frames per second (the paper's camera: up to 90).
        position_std: standard deviation of a detected position on the table (m).
        rod_std: standard deviation of a measured opponent rod position (m).
        drop_rate: share of frames in which the detector misses a visible ball.
        hide_under_figurines: the ball is not seen while a figurine's head covers it.
        latency_s: from the frame to the drives acting (s); the filter predicts this far
            ahead, as on the real table.
        latency_jitter_s: each frame is late by a further uniform draw from
            [0, latency_jitter_s] (s), as a real camera's transfer and a busy computer make
            it; frames still reach the filter in the order they were taken (a frame through
            early waits for the one before it), and the filter still predicts ``latency_s``
            ahead.
        seed: draw the camera's errors from a generator of their own, seeded by this and
            each episode's seed, instead of the environment's. The balls stay the same and
            only the detections change with it, so several seeds measure how much a result
            owes to the camera's draws. None (the default) draws from the environment's
            generator.
    """

    fps: float = 60.0
    position_std: float = 0.002
    rod_std: float = 0.003
    drop_rate: float = 0.02
    hide_under_figurines: bool = True
    latency_s: float = 0.03
    latency_jitter_s: float = 0.0
    seed: int | None = None

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> CameraNoise:
        values = dict(values or {})
        allowed = {f.name for f in fields(cls)}
        unknown = set(values) - allowed
        if unknown:
            raise ValueError(
                f"unknown camera_noise key(s) {sorted(unknown)}; allowed: "
                f"{', '.join(sorted(allowed))}"
            )
        noise = cls(**values)
        for name in ("fps",):
            if not getattr(noise, name) > 0:
                raise ValueError(
                    f"camera_noise {name} must be positive, got {getattr(noise, name)}"
                )
        for name in ("position_std", "rod_std", "latency_s", "latency_jitter_s"):
            value = getattr(noise, name)
            try:
                number = float(value)
            except (TypeError, ValueError):
                number = math.nan
            if isinstance(value, bool) or not 0 <= number < math.inf:
                raise ValueError(
                    f"camera_noise {name} must be a finite number, 0 or more, got {value!r}"
                )
        if not 0 <= noise.drop_rate < 1:
            raise ValueError(f"camera_noise drop_rate must lie in [0, 1), got {noise.drop_rate}")
        seed = noise.seed
        if seed is not None and (
            isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0
        ):
            raise ValueError(
                f"camera_noise seed must be an integer, 0 or more, or None, got {seed!r}"
            )
        return noise
