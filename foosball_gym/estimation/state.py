"""From camera measurements and encoder readings to the observation a policy was trained on."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from foosball_gym import table
from foosball_gym.estimation.kalman import BallFilter, RodFilter
from foosball_gym.policy_io.observations import ObservationBuilder


class TableStateEstimator:
    """Kalman filters for the ball and the opponent's rods, feeding the task's observation
    builder, so the policy gets exactly the vector the environment would give it.

    The policy's own rods come from the drives' encoders; the ball and the opponent's rods
    (prismatic joints only: all the camera can see) from the camera. Every estimate is
    predicted ``latency_s`` ahead, to cover the time from the frame to the drives acting.

    Args:
        builder: the task's observation builder.
        latency_s: how far ahead to predict (s).
        ball: the ball's filter (default settings if None).
        rod_measurement_std: standard deviation of a measured rod position (m).
    """

    def __init__(
        self,
        builder: ObservationBuilder,
        latency_s: float = 0.03,
        ball: BallFilter | None = None,
        rod_measurement_std: float = 0.003,
    ) -> None:
        if latency_s < 0:
            raise ValueError(f"latency_s must not be negative, got {latency_s}")
        self.builder = builder
        self.latency = latency_s
        self.ball = ball if ball is not None else BallFilter()
        # The rods the camera tracks: the opponent's, and still obstacles (observed by slide).
        tracked = list(builder.tracked_rods)
        self.rods = {
            name: RodFilter(table.rod(name).slide_limit, rod_measurement_std) for name in tracked
        }
        self._slot = {name: builder.rods_in_play.index(name) for name in tracked}
        self._n = len(builder.rods_in_play)

    def update(
        self,
        t: float,
        ball_xy: tuple[float, float] | None,
        rod_slides: Mapping[str, float | None] | None = None,
    ) -> None:
        """Take one frame's measurements (None where nothing was seen).

        Args:
            t: when the frame was taken (s).
            ball_xy: the detected ball on the table (m), or None.
            rod_slides: measured slide values of tracked rods (a rod left out: not seen).
        """
        slides = rod_slides or {}
        unknown = set(slides) - set(self.rods)
        if unknown:
            raise ValueError(
                f"no tracked rod called {sorted(unknown)}; tracked: {', '.join(self.rods)}"
            )
        self.ball.update(t, ball_xy)
        for name, rod_filter in self.rods.items():
            rod_filter.update(t, slides.get(name))

    def new_ball(self) -> None:
        """A ball put in play somewhere else: what was known of the last one is forgotten,
        as an environment's estimate is at its reset. The rods' estimates stay."""
        self.ball.forget()

    def ball_estimate(self) -> tuple[float, float, float, float]:
        """The ball, predicted ahead by the latency."""
        return self.ball.predict_ahead(self.latency)

    def observation(self, own_pos: Sequence[float], own_vel: Sequence[float]) -> np.ndarray:
        """The observation, from the encoders' joint values and the filters' estimates.

        Args:
            own_pos: joint values in the builder's layout (slides of
                ``builder.rods_in_play``, then spins); the tracked rods' entries are replaced.
            own_vel: joint velocities, in the same layout.
        """
        pos, vel = list(own_pos), list(own_vel)
        if len(pos) != 2 * self._n or len(vel) != 2 * self._n:
            raise ValueError(f"own_pos and own_vel need {2 * self._n} values (slides, spins)")
        for name, rod_filter in self.rods.items():
            i = self._slot[name]
            pos[i], vel[i] = rod_filter.predict_ahead(self.latency)
            pos[self._n + i] = vel[self._n + i] = 0.0  # the camera cannot see rotations
        return self.builder.build(pos, vel, self.ball_estimate())
