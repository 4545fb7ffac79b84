"""From pixels to the table plane and back, with a calibrated camera."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from foosball_gym import table
from foosball_gym.camera import CameraModel


@dataclass
class CameraCalibration:
    """A calibrated camera, in OpenCV's conventions.

    Attributes:
        K: 3x3 intrinsic matrix.
        dist: distortion coefficients (k1, k2, p1, p2, k3).
        rvec, tvec: world to camera rotation (Rodrigues vector) and translation, metres.
    """

    K: np.ndarray
    dist: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray

    def __post_init__(self) -> None:
        self.K = np.asarray(self.K, dtype=float).reshape(3, 3)
        self.dist = np.asarray(self.dist, dtype=float).reshape(-1)
        self.rvec = np.asarray(self.rvec, dtype=float).reshape(3)
        self.tvec = np.asarray(self.tvec, dtype=float).reshape(3)
        self._R = cv2.Rodrigues(self.rvec)[0]
        self._centre = -self._R.T @ self.tvec

    @classmethod
    def from_camera_model(cls, model: CameraModel) -> CameraCalibration:
        """The exact calibration of the simulator's camera."""
        rvec = cv2.Rodrigues(model.rotation())[0]
        return cls(model.intrinsics(), np.zeros(5), rvec, model.translation())

    @property
    def centre(self) -> np.ndarray:
        """The camera's position in the world (m)."""
        return self._centre

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) to pixels (N, 2)."""
        points = np.atleast_2d(np.asarray(points, dtype=float))
        uv, _ = cv2.projectPoints(points, self.rvec, self.tvec, self.K, self.dist)
        return uv.reshape(-1, 2)

    def pixel_to_table(self, uv: np.ndarray, z: float = table.BALL_RADIUS) -> np.ndarray:
        """Back-project pixels onto the horizontal plane at height ``z``.

        Args:
            uv: (2,) or (N, 2) pixel coordinates.
            z: height of the plane (default: the ball's centre).

        Returns:
            (2,) or (N, 2) world x, y.
        """
        uv = np.asarray(uv, dtype=float)
        single = uv.ndim == 1
        norm = cv2.undistortPoints(uv.reshape(-1, 1, 2), self.K, self.dist).reshape(-1, 2)
        rays = np.column_stack([norm, np.ones(len(norm))]) @ self._R  # camera → world
        s = (z - self._centre[2]) / rays[:, 2]
        xy = self._centre[:2] + s[:, None] * rays[:, :2]
        return xy[0] if single else xy

    def to_dict(self) -> dict[str, Any]:
        return {
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "rvec": self.rvec.tolist(),
            "tvec": self.tvec.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CameraCalibration:
        try:
            return cls(data["K"], data.get("dist", [0.0] * 5), data["rvec"], data["tvec"])
        except (KeyError, ValueError, TypeError) as err:
            raise ValueError(
                f"a camera calibration needs K (3x3), rvec (3), tvec (3) and optionally dist; "
                f"got {sorted(data) if isinstance(data, dict) else data!r} ({err})"
            ) from None
