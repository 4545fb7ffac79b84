"""Kalman filters for what the camera sees: the ball, and the opponent's rods.

Both are constant-velocity filters (filterpy) that take measurements at whatever times frames
arrive, carry on predicting through missed detections, and say when their estimate has gone
stale. The ball's filter knows the walls: its prediction bounces off them. It mixes three models
of the ball (filterpy's interacting multiple models): kicked, rolling and lying still.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import IMMEstimator, KalmanFilter

from foosball_gym import table

_WALL_Y = table.BALL_LIMIT_Y
_WALL_X = table.BALL_LIMIT_X


def bounce(
    x: float, y: float, vx: float, vy: float, restitution: float = table.BALL_RESTITUTION
) -> tuple[float, float, float, float]:
    """A ball state past a wall, brought back into the field as the bounce would.

    Side walls at |y| = 0.34 - r; end walls at |x| = 0.60 - r except in the goal mouth. A ball
    moving into a wall bounces: the velocity across the wall reverses and shrinks by
    ``restitution``, and the velocity along it by what the wall's friction takes
    (:func:`foosball_gym.table.wall_bounce_along_ratio`: 16 % at 45 degrees), and so does the
    distance travelled past the wall in each direction. A ball past a wall but already moving
    back (a noisy detection put it there) is put onto the wall: flipping its velocity again
    would send it out once more.
    """
    for _ in range(4):  # a long prediction can bounce more than once
        if abs(y) > _WALL_Y:
            y, vy, x, vx = _off_wall(y, vy, x, vx, _WALL_Y, restitution)
        elif abs(x) > _WALL_X and abs(y) > table.GOAL_HALF_WIDTH:
            x, vx, y, vy = _off_wall(x, vx, y, vy, _WALL_X, restitution)
        else:
            break
    return x, y, vx, vy


def _off_wall(
    across: float, v_across: float, along: float, v_along: float, wall: float, e: float
) -> tuple[float, float, float, float]:
    """:func:`bounce` at one wall, in its own axes: the position and velocity across it, then
    along it."""
    edge = math.copysign(wall, across)
    if across * v_across <= 0:
        return edge, v_across, along, v_along
    keep = table.wall_bounce_along_ratio(v_across / v_along) if v_along else 1.0
    # The time spent past the wall, travelled again at the velocities the bounce leaves.
    past = (across - edge) / v_across
    along -= (1.0 - keep) * v_along * past
    return edge - e * (across - edge), -e * v_across, along, keep * v_along


def _bounced(x: np.ndarray, restitution: float) -> np.ndarray:
    """A filter's state column (x, y, vx, vy) brought back into the field."""
    px, py, vx, vy = (float(v) for v in np.ravel(x))
    return np.array(bounce(px, py, vx, vy, restitution), dtype=np.float64).reshape(4, 1)


class _DetectionModel(KalmanFilter):
    """A filterpy filter whose detections' likelihood is worked out in closed form: SciPy's
    general one took a third of the ball filter's time, which the environments pay every
    frame."""

    @property
    def log_likelihood(self) -> float:
        if self._log_likelihood is None:  # type: ignore[has-type]
            (a, b), (c, d) = self.S
            y0, y1 = self.y.ravel()
            det = a * d - b * c
            distance = (d * y0 * y0 - (b + c) * y0 * y1 + a * y1 * y1) / det
            self._log_likelihood = -0.5 * (distance + math.log(det)) - math.log(2 * math.pi)
        return self._log_likelihood


@functools.lru_cache(maxsize=64)
def _process_noise(dt: float, acceleration_var: float) -> np.ndarray:
    """A constant-velocity model's process noise over ``dt`` (frames mostly come at one rate,
    so a handful of values serve every frame)."""
    Q = Q_discrete_white_noise(dim=2, dt=dt, var=acceleration_var, block_size=2, order_by_dim=False)
    Q.setflags(write=False)
    return Q


# The still model: the position stays, the velocity is nought.
_STILL = np.diag([1.0, 1.0, 0.0, 0.0])
_STILL.setflags(write=False)


@functools.lru_cache(maxsize=64)
def _still_noise(dt: float, drift_speed: float) -> np.ndarray:
    """The still model's noise over ``dt``: a creep of ``drift_speed``, and a trace of
    velocity that keeps its covariance invertible."""
    Q = np.diag([(drift_speed * dt) ** 2] * 2 + [1e-8] * 2)
    Q.setflags(write=False)
    return Q


class BallFilter:
    """The ball's position and velocity from noisy, irregular, sometimes missing detections.

    Three models run side by side and are mixed by how well each explains the detections
    (filterpy's interacting multiple models). Two keep the ball's velocity: a ball that rolls
    or crosses the field (``rolling_acceleration_std``), and one that a figurine or a wall
    changes within a frame (``acceleration_std``). The third holds a ball lying still
    (``still_drift_speed``). The rolling model averages the camera's noise over many frames,
    where one model fast enough for a kick would follow every frame's error: 2 mm on a ball at
    rest turns a shot from the goal's edge several degrees. The still model averages further,
    since it has no velocity to follow the noise with: an aimed kick turns about 5 degrees per
    millimetre of the ball's offset.

    Args:
        measurement_std: standard deviation of a detected position (m).
        acceleration_std: the random acceleration the kicked model allows (m/s^2): figurines
            and walls change the ball's velocity abruptly.
        rolling_acceleration_std: the random acceleration the rolling model allows (m/s^2);
            0 or None leaves it out.
        switch_probability: the chance per frame that a moving ball goes from the kicked model
            to the rolling one or back.
        still_drift_speed: how fast the still model lets a ball at rest creep (m/s); 0 or None
            leaves it out.
        still_switch_probability: the chance per frame that a moving ball comes to rest; a ball
            at rest is set moving ten times as readily (a kick comes without warning).
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
        rolling_acceleration_std: float | None = 1.0,
        switch_probability: float = 0.05,
        still_drift_speed: float | None = 0.006,
        still_switch_probability: float = 0.001,
        stale_after: float = 0.2,
        reset_after: float = 0.5,
        wall_restitution: float = table.BALL_RESTITUTION,
    ) -> None:
        if not 0.0 < switch_probability < 1.0:
            raise ValueError(f"switch_probability must be in (0, 1), got {switch_probability}")
        if not 0.0 < still_switch_probability < 0.1:
            raise ValueError(
                "still_switch_probability must be in (0, 0.1) (a ball at rest is set moving ten "
                f"times as readily), got {still_switch_probability}"
            )
        stds = [acceleration_std] + ([rolling_acceleration_std] if rolling_acceleration_std else [])
        if any(not std > 0 for std in stds):
            raise ValueError(f"acceleration stds must be positive, got {stds}")
        if still_drift_speed is not None and still_drift_speed < 0:
            raise ValueError(
                f"still_drift_speed must be positive, or 0 or None to leave the still model "
                f"out, got {still_drift_speed}"
            )
        self.still_drift_speed = still_drift_speed or None
        n_moving = len(stds)
        n = n_moving + (1 if self.still_drift_speed else 0)
        self.models = []
        for _ in range(n):
            kf = _DetectionModel(dim_x=4, dim_z=2)
            kf.H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
            kf.R = np.eye(2) * measurement_std**2
            self.models.append(kf)
        if self.still_drift_speed:
            self.models[-1].F = _STILL
        self.acceleration_vars = [std**2 for std in stds]
        # Row i: from model i. The moving models switch between themselves at
        # switch_probability and come to rest at still_switch_probability.
        switch = np.zeros((n, n))
        if n_moving > 1:
            switch[:n_moving, :n_moving] = switch_probability / (n_moving - 1)
        if n > n_moving:
            switch[:n_moving, -1] = still_switch_probability
            switch[-1, :n_moving] = 10 * still_switch_probability / n_moving
        np.fill_diagonal(switch, 0.0)
        np.fill_diagonal(switch, 1.0 - switch.sum(axis=1))
        self._switch = switch
        self.imm: IMMEstimator | None = None
        self.x = np.zeros((4, 1))
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
        x, y, vx, vy = self.x.ravel()
        return float(x), float(y), float(vx), float(vy)

    @property
    def kicked_probability(self) -> float:
        """How likely the kicked model is, by the detections so far (1 with one model)."""
        return 1.0 if self.imm is None else float(self.imm.mu[0])

    def _start(self, t: float, xy: tuple[float, float]) -> None:
        for kf in self.models:
            kf.x = np.array([[xy[0]], [xy[1]], [0.0], [0.0]])
            # Position as measured; velocity unknown, up to a hard shot.
            kf.P = np.diag([kf.R[0, 0], kf.R[1, 1], 10.0**2, 10.0**2])
        # A new ball may come at any speed: the kicked model leads until the frames say.
        mu = np.full(len(self.models), 0.5 / max(len(self.models) - 1, 1))
        mu[0] = 0.5 if len(self.models) > 1 else 1.0
        self.imm = IMMEstimator(self.models, mu, self._switch) if len(self.models) > 1 else None
        self.x = self.models[0].x.copy()
        self.t = self.last_seen = t

    def forget(self) -> None:
        """Drop the estimate: the next detection starts afresh, at any time (a new ball put
        in play). Until then the state is zeros, as before the first detection."""
        self.x = np.zeros((4, 1))
        self.imm = None
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
        was_stale, held = self.stale, self.x.copy()
        if dt > 0:
            F = np.array([[1.0, 0, dt, 0], [0, 1.0, 0, dt], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
            for kf, var in zip(self.models, self.acceleration_vars):
                kf.F = F
                kf.Q = _process_noise(dt, var)
            if self.still_drift_speed:
                self.models[-1].Q = _still_noise(dt, self.still_drift_speed)
            (self.imm or self.models[0]).predict()
            self._keep_inside()
            self.t = t
        if xy is not None:
            (self.imm or self.models[0]).update(np.asarray(xy, dtype=float).reshape(2, 1))
            self._keep_inside()
            self.last_seen = t
        elif self.stale:
            # Every model held at the one estimate, so that mixing them moves it no more.
            if was_stale:
                self.x = held
            self.x[2:] = 0.0
            for kf in self.models:
                kf.x = self.x.copy()

    def _keep_inside(self) -> None:
        """Bounce the estimate back into the field if the model or a detection took it out:
        every model's, and the mixed one."""
        for kf in self.models:
            kf.x = _bounced(kf.x, self.restitution)
        # As differences from the first model: models that agree mix to exactly their value.
        first = self.models[0].x
        mu = [1.0] if self.imm is None else self.imm.mu
        mixed = first + sum(m * (kf.x - first) for m, kf in zip(mu, self.models))
        self.x = _bounced(mixed, self.restitution)

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
