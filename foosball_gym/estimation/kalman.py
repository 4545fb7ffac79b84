"""Kalman filters for what the camera sees: the ball, and the opponent's rods.

Both are constant-velocity filters (filterpy) that take measurements at whatever times frames
arrive, carry on predicting through missed detections, and say when their estimate has gone
stale. The ball's filter knows the walls: its prediction bounces off them.
"""

from __future__ import annotations

import math

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter

from foosball_gym import table

_WALL_Y = table.BALL_LIMIT_Y
_WALL_X = table.BALL_LIMIT_X


def bounce(
    x: float, y: float, vx: float, vy: float, restitution: float = table.BALL_RESTITUTION
) -> tuple[float, float, float, float]:
    """A ball state past a wall, brought back into the field as the bounce would.

    Side walls at |y| = 0.34 - r; end walls at |x| = 0.60 - r except in the goal mouth. A ball
    moving into a wall bounces: the velocity across the wall reverses and shrinks by
    ``restitution``, and so does the distance travelled past the wall. A ball past a wall but
    already moving back (a noisy detection put it there) is put onto the wall: flipping its
    velocity again would send it out once more.
    """
    e = restitution
    for _ in range(4):  # a long prediction can bounce more than once
        if abs(y) > _WALL_Y:
            edge = math.copysign(_WALL_Y, y)
            y, vy = (edge - e * (y - edge), -e * vy) if y * vy > 0 else (edge, vy)
        elif abs(x) > _WALL_X and abs(y) > table.GOAL_HALF_WIDTH:
            edge = math.copysign(_WALL_X, x)
            x, vx = (edge - e * (x - edge), -e * vx) if x * vx > 0 else (edge, vx)
        else:
            break
    return x, y, vx, vy


class BallFilter:
    """The ball's position and velocity from noisy, irregular, sometimes missing detections.

    Args:
        measurement_std: standard deviation of a detected position (m).
        acceleration_std: the random acceleration the model allows (m/s^2): a ball rolls
            straight, but figurines and walls change its velocity abruptly.
        stale_after: seconds without a detection after which :attr:`stale` is true and the
            estimate stops moving: a ball unseen this long is held under a figurine or a hand,
            not rolling on as it was last seen.
        reset_after: seconds without a detection after which the next one starts afresh
            (a ball taken off the table and put back somewhere else).
        wall_restitution: the share of its speed across a wall that a ball keeps in a bounce.
    """

    def __init__(
        self,
        measurement_std: float = 0.002,
        acceleration_std: float = 40.0,
        stale_after: float = 0.2,
        reset_after: float = 0.5,
        wall_restitution: float = table.BALL_RESTITUTION,
    ) -> None:
        self.kf = KalmanFilter(dim_x=4, dim_z=2)
        self.kf.H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
        self.kf.R = np.eye(2) * measurement_std**2
        self.acceleration_var = acceleration_std**2
        self.stale_after = stale_after
        self.reset_after = reset_after
        self.restitution = wall_restitution
        self.t: float | None = None
        self.last_seen: float | None = None

    @property
    def initialised(self) -> bool:
        return self.t is not None

    @property
    def stale(self) -> bool:
        return (
            self.last_seen is None or self.t is None or self.t - self.last_seen > self.stale_after
        )

    @property
    def state(self) -> tuple[float, float, float, float]:
        """x, y, vx, vy now (m, m/s); zeros before the first detection."""
        x, y, vx, vy = self.kf.x.ravel()
        return float(x), float(y), float(vx), float(vy)

    def _start(self, t: float, xy: tuple[float, float]) -> None:
        self.kf.x = np.array([[xy[0]], [xy[1]], [0.0], [0.0]])
        # Position as measured; velocity unknown, up to a hard shot.
        self.kf.P = np.diag([self.kf.R[0, 0], self.kf.R[1, 1], 10.0**2, 10.0**2])
        self.t = self.last_seen = t

    def forget(self) -> None:
        """Drop the estimate: the next detection starts afresh, at any time (a new ball put
        in play). Until then the state is zeros, as before the first detection."""
        self.kf.x = np.zeros((4, 1))
        self.t = self.last_seen = None

    def update(self, t: float, xy: tuple[float, float] | None) -> None:
        """Advance to time ``t`` and take the detection made then, if any."""
        if self.t is None or (
            xy is not None and self.last_seen is not None and t - self.last_seen > self.reset_after
        ):
            if xy is not None:
                self._start(t, xy)
            return
        dt = t - self.t
        if dt < 0:
            raise ValueError(f"measurements must come in time order (t went from {self.t} to {t})")
        if dt > 0:
            self.kf.F = np.array([[1.0, 0, dt, 0], [0, 1.0, 0, dt], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
            self.kf.Q = Q_discrete_white_noise(
                dim=2, dt=dt, var=self.acceleration_var, block_size=2, order_by_dim=False
            )
            self.kf.predict()
            self._keep_inside()
            self.t = t
        if xy is not None:
            self.kf.update(np.asarray(xy, dtype=float).reshape(2, 1))
            self._keep_inside()
            self.last_seen = t
        elif self.stale:
            self.kf.x[2:] = 0.0

    def _keep_inside(self) -> None:
        """Bounce the estimate back into the field if the model or a detection took it out."""
        self.kf.x = np.array(bounce(*self.state, self.restitution), dtype=float).reshape(4, 1)

    def predict_ahead(self, latency: float) -> tuple[float, float, float, float]:
        """Where the ball will be ``latency`` seconds after the last update, walls included."""
        x, y, vx, vy = self.state
        return bounce(x + vx * latency, y + vy * latency, vx, vy, self.restitution)


class RodFilter:
    """An opponent rod's prismatic position and velocity from its figurines' detections.

    Args:
        limit: the rod's slide limit (the estimate stays within ±limit).
        measurement_std: standard deviation of a measured slide value (m).
        acceleration_std: the random acceleration the model allows (m/s^2).
        stale_after: seconds without a measurement after which :attr:`stale` is true and the
            estimate holds still where it got to (a hand over the rod, not a rod that keeps
            moving).
    """

    def __init__(
        self,
        limit: float,
        measurement_std: float = 0.003,
        acceleration_std: float = 15.0,
        stale_after: float = 0.2,
    ) -> None:
        self.limit = limit
        self.kf = KalmanFilter(dim_x=2, dim_z=1)
        self.kf.H = np.array([[1.0, 0.0]])
        self.kf.R = np.array([[measurement_std**2]])
        self.acceleration_var = acceleration_std**2
        self.stale_after = stale_after
        self.t: float | None = None
        self.last_seen: float | None = None

    @property
    def stale(self) -> bool:
        """No measurement for ``stale_after`` seconds, or none yet."""
        if self.t is None or self.last_seen is None:
            return True
        return self.t - self.last_seen > self.stale_after

    @property
    def state(self) -> tuple[float, float]:
        pos, vel = self.kf.x.ravel()
        return float(pos), float(vel)

    def update(self, t: float, slide: float | None) -> None:
        if self.t is None:
            if slide is not None:
                self.kf.x = np.array([[slide], [0.0]])
                self.kf.P = np.diag([self.kf.R[0, 0], 4.0**2])
                self.t = self.last_seen = t
            return
        dt = t - self.t
        if dt < 0:
            raise ValueError(f"measurements must come in time order (t went from {self.t} to {t})")
        if dt > 0:
            self.kf.F = np.array([[1.0, dt], [0.0, 1.0]])
            self.kf.Q = Q_discrete_white_noise(dim=2, dt=dt, var=self.acceleration_var)
            self.kf.predict()
            self.t = t
        if slide is not None:
            self.kf.update(np.array([[slide]]))
            self.last_seen = t
        elif self.stale:
            self.kf.x[1] = 0.0
        pos, vel = self.state
        if abs(pos) > self.limit:  # the rod cannot leave its range; it stops there
            self.kf.x = np.array([[math.copysign(self.limit, pos)], [0.0]])

    def predict_ahead(self, latency: float) -> tuple[float, float]:
        pos, vel = self.state
        ahead = pos + vel * latency
        if abs(ahead) > self.limit:
            return math.copysign(self.limit, ahead), 0.0
        return ahead, vel
