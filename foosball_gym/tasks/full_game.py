"""The full game: four rods a side."""

from __future__ import annotations

from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.policies.ladder import FULL_GAME_LADDER
from foosball_gym.policy_io.task import Layout
from foosball_gym.tasks.base import Start
from foosball_gym.tasks.match import DEAD_BALL_STEPS, GameTask


class FullGameTask(GameTask):
    """All eight rods; a kick-off from a side wall. Success is scoring (in a continuous match:
    being ahead)."""

    ladder = FULL_GAME_LADDER

    def __init__(
        self,
        *,
        continuous: bool = False,
        first_to: int = 0,
        match_seconds: float | None = None,
        dead_ball_steps: int = DEAD_BALL_STEPS,
    ) -> None:
        super().__init__(
            continuous=continuous,
            first_to=first_to,
            match_seconds=match_seconds,
            dead_ball_steps=dead_ball_steps,
        )
        home = tuple(r.name for r in table.team_rods(table.HOME))
        away = tuple(r.name for r in table.team_rods(table.AWAY))
        self.layout = Layout(controlled=home, joints="both", opponent=away)

    def sample_start(
        self,
        rng: np.random.Generator,
        ball_position=None,
        ball_velocity=None,
        options: dict[str, Any] | None = None,
    ) -> Start:
        side = 1.0 if rng.random() < 0.5 else -1.0
        position = (0.0, 0.3 * side)
        vx = float(rng.uniform(0.25, 1.0)) * (1.0 if rng.random() < 0.5 else -1.0)
        velocity = (vx, -side * float(rng.uniform(1.0, 2.0)))
        if ball_position is not None:
            position = ball_position
        if ball_velocity is not None:
            velocity = ball_velocity
        return Start([0.0] * 8, [0.0] * 8, position, velocity)
