"""The camera above the table, as a pinhole model (no simulator needed)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera above the table (the real table's camera, simulated).

    ``position`` is in world metres; the camera looks straight down at the origin with the
    image's up direction along +y, so +x is to the right of the image.
    """

    width: int
    height: int
    height_above_table: float = 1.0
    horizontal_half_extent: float = 0.75  # metres of table visible either side of x = 0

    @property
    def vertical_fov_deg(self) -> float:
        half_h = self.horizontal_half_extent * self.height / self.width
        return math.degrees(2 * math.atan(half_h / self.height_above_table))

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (square pixels)."""
        return self.width / 2 / (self.horizontal_half_extent / self.height_above_table)

    def intrinsics(self) -> np.ndarray:
        f = self.focal_px
        return np.array([[f, 0, self.width / 2], [0, f, self.height / 2], [0, 0, 1]], dtype=float)

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) to pixel coordinates (N, 2): column, row."""
        points = np.atleast_2d(points)
        depth = self.height_above_table - points[:, 2]
        f = self.focal_px
        u = self.width / 2 + f * points[:, 0] / depth
        v = self.height / 2 - f * points[:, 1] / depth
        return np.stack([u, v], axis=1)
