"""Block: the home keeper stops shots at its goal."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.policies.scripted import ScriptedKeeper
from foosball_gym.policy_io.task import Layout
from foosball_gym.tasks.base import Start, Task
from foosball_gym.tasks.serves import Shots


class BlockTask(Task):
    """Shots from the away half at the home goal; success is conceding none."""

    def __init__(
        self,
        *,
        speed_range: tuple[float, float] = (2.0, 7.0),
        serve_x_range: tuple[float, float] = (0.0, 0.4),
        serve_y_range: tuple[float, float] = (-0.3, 0.3),
        bank_share: float = 0.0,
        double_bank_share: float = 0.0,
        bank_aim: str = "model",
        beside_mouth: float = 0.0,
        rebound_share: float = 0.0,
    ) -> None:
        self.shots = Shots.checked(
            speed_range,
            serve_x_range,
            serve_y_range,
            bank_share,
            double_bank_share,
            bank_aim,
            beside_mouth,
            rebound_share,
        )
        self.layout = Layout(controlled=("home_keeper",), joints="slide")

    def sample_start(
        self,
        rng: np.random.Generator,
        ball_position=None,
        ball_velocity=None,
        options: dict[str, Any] | None = None,
    ) -> Start:
        position, velocity = self.shots.start(rng)
        if ball_position is not None:
            position = ball_position
            velocity = self.shots.aim(rng, position, table.HOME)
        if ball_velocity is not None:
            velocity = ball_velocity
        return Start([0.0], [0.0], position, velocity)

    def served_shots(self) -> Shots:
        return self.shots

    def scripted_policy(self, names: Sequence[str], precise_state: bool = True) -> ScriptedKeeper:
        return ScriptedKeeper(names)

    def success(self, goals_for: int, goals_against: int) -> bool:
        return goals_against == 0
