"""Block: the home keeper stops shots at its goal."""

from __future__ import annotations

from typing import Any

import numpy as np

from foosball_gym import table as T
from foosball_gym.interface.task import Layout
from foosball_gym.tasks.base import Start, Task
from foosball_gym.tasks.serves import (
    SHOT_SPEED_LIMITS,
    check_range,
    random_shot_start,
    shot_at_goal,
)


class BlockTask(Task):
    """Shots from the away half at the home goal; success is conceding none."""

    def __init__(self, *, speed_range: tuple[float, float] = (2.0, 7.0)) -> None:
        self.speed_range = check_range("speed_range", speed_range, *SHOT_SPEED_LIMITS)
        self.layout = Layout(controlled=("home_keeper",), joints="slide")

    def sample_start(
        self,
        rng: np.random.Generator,
        ball_position=None,
        ball_velocity=None,
        options: dict[str, Any] | None = None,
    ) -> Start:
        position, velocity = random_shot_start(rng, self.speed_range)
        if ball_position is not None:
            position = ball_position
            velocity = shot_at_goal(rng, position, self.speed_range, T.HOME)
        if ball_velocity is not None:
            velocity = ball_velocity
        return Start([0.0], [0.0], position, velocity)

    def success(self, goals_for: int, goals_against: int) -> bool:
        return goals_against == 0
