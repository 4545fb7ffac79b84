"""Observations as the real table makes them: a simulated camera and the real Kalman filter.

With ``estimated_state=True`` an environment does not hand the policy the simulator's true ball
and opponent rods. It passes them through a simulated camera (frame rate, detection noise,
dropped detections, the ball hidden under a figurine's head, latency and its jitter) and then
through the very :class:`~foosball_gym.estimation.TableStateEstimator` that ``foosball play``
runs on the real table. The paper found that training on such estimates narrows the gap
between simulation and the real table.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from foosball_gym import table
from foosball_gym.camera import CameraNoise
from foosball_gym.policy_io.observations import ObservationBuilder

if TYPE_CHECKING:
    from foosball_gym.estimation import TableStateEstimator

__all__ = ["CameraNoise", "EstimatedState"]


class EstimatedState:
    """The camera and filter between the simulator's true state and the policy.

    Args:
        builder: the task's observation builder.
        noise: the camera's errors.
        rng: the environment's random generator (so estimates are seeded too); the camera
            draws from a generator of its own where ``noise.seed`` is set.
    """

    def __init__(
        self, builder: ObservationBuilder, noise: CameraNoise, rng: np.random.Generator
    ) -> None:
        try:
            from foosball_gym.estimation import TableStateEstimator
        except ImportError as err:
            raise ImportError(
                f"estimated_state needs filterpy ({err.name} is missing): "
                'pip install -e ".[hardware]"'
            ) from err
        self._estimator_class = TableStateEstimator
        self.builder = builder
        self.noise = noise
        self.rng = rng if noise.seed is None else np.random.default_rng(int(noise.seed))
        self.tracked = list(builder.tracked_rods)
        self._slot = {name: builder.rods_in_play.index(name) for name in self.tracked}
        self.estimator = self._new_estimator()
        # Frames taken and not yet seen: when each is due, then the filter's update.
        self._pending: deque[tuple[float, float, tuple[float, float] | None, dict]] = deque()
        self._t = 0.0
        self._next_frame = 0.0
        self._ball_before: Sequence[float] = (0.0, 0.0, 0.0, 0.0)

    def reseed(self, env_rng: np.random.Generator, episode_seed: int | None) -> None:
        """Take the generator the camera draws from for the episode that starts.

        With ``noise.seed`` unset it is the environment's. With it set, an episode given a
        seed gets a generator of that seed and ``noise.seed``, so episode K is seen through
        the same detections whatever ran before it; an episode without one goes on drawing
        from the generator before it.
        """
        if self.noise.seed is None:
            self.rng = env_rng
        elif episode_seed is not None:
            self.rng = np.random.default_rng([int(self.noise.seed), int(episode_seed)])

    def _new_estimator(self) -> TableStateEstimator:
        return self._estimator_class(self.builder, latency_s=self.noise.latency_s)

    def reset(self, ball: Sequence[float], pos: Sequence[float], figurines: np.ndarray) -> None:
        """Start afresh; the first frame is taken now and seen at once."""
        self.estimator = self._new_estimator()
        self._pending.clear()
        self._t = 0.0
        self._next_frame = 1.0 / self.noise.fps
        self._ball_before = ball
        self.estimator.update(0.0, *self._measure(ball[0], ball[1], pos, figurines))

    def advance(
        self, dt: float, ball: Sequence[float], pos: Sequence[float], figurines: np.ndarray
    ) -> None:
        """The simulation moved on by ``dt``: take the frames that fell in it and feed the
        filter those whose latency has passed."""
        start, self._t = self._t, self._t + dt
        bx0, by0 = self._ball_before[0], self._ball_before[1]
        while self._next_frame <= self._t + 1e-12:
            a = (self._next_frame - start) / dt
            x, y = bx0 + a * (ball[0] - bx0), by0 + a * (ball[1] - by0)
            measured = self._measure(x, y, pos, figurines)
            due = self._next_frame + self.noise.latency_s
            if self.noise.latency_jitter_s:
                due += float(self.rng.uniform(0.0, self.noise.latency_jitter_s))
            self._pending.append((due, self._next_frame, *measured))
            self._next_frame += 1.0 / self.noise.fps
        self._ball_before = ball
        # In the order taken: a frame due early waits for the one before it.
        while self._pending and self._pending[0][0] <= self._t + 1e-12:
            self.estimator.update(*self._pending.popleft()[1:])

    def _measure(
        self, x: float, y: float, pos: Sequence[float], figurines: np.ndarray
    ) -> tuple[tuple[float, float] | None, dict]:
        noise, rng = self.noise, self.rng
        slides = {
            name: float(pos[i] + rng.normal(0.0, noise.rod_std)) for name, i in self._slot.items()
        }
        hidden = noise.hide_under_figurines and bool(
            np.any(
                (np.abs(figurines[:, 0] - x) < table.FIGURINE_SIZE[0] / 2)
                & (np.abs(figurines[:, 1] - y) < table.FIGURINE_SIZE[1] / 2)
            )
        )
        if hidden or rng.random() < noise.drop_rate:
            return None, slides
        return (
            x + rng.normal(0.0, noise.position_std),
            y + rng.normal(0.0, noise.position_std),
        ), slides

    def observation(self, pos: Sequence[float], vel: Sequence[float]) -> np.ndarray:
        return self.estimator.observation(pos, vel)
