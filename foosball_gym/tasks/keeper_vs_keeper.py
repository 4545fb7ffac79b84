"""Keeper against keeper: the game the paper's real table plays."""

from __future__ import annotations

from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.policies.ladder import KEEPER_LADDER
from foosball_gym.policy_io.task import Layout
from foosball_gym.tasks.base import Start
from foosball_gym.tasks.match import DEAD_BALL_STEPS, GameTask
from foosball_gym.tasks.serves import check_share, resting_in_front_of


class KeeperVsKeeperTask(GameTask):
    """The two keepers; the ball starts at rest in front of one. Success is scoring (in a
    continuous match: being ahead)."""

    ladder = KEEPER_LADDER

    def __init__(
        self,
        *,
        continuous: bool = False,
        first_to: int = 0,
        match_seconds: float | None = None,
        dead_ball_steps: int = DEAD_BALL_STEPS,
        home_serve_share: float = 0.5,
    ) -> None:
        # A match of many serves: two sound keepers rarely score, so one serve a game leaves
        # most games drawn and tells little about which keeper is better.
        super().__init__(
            continuous=continuous,
            first_to=first_to,
            match_seconds=match_seconds,
            dead_ball_steps=dead_ball_steps,
        )
        self.home_serve_share = check_share("home_serve_share", home_serve_share)
        self.layout = Layout(controlled=("home_keeper",), joints="both", opponent=("away_keeper",))

    def serve_options(self) -> dict[str, Any]:
        return {"home_serve_share": self.home_serve_share}

    def set_serves(self, **options: Any) -> None:
        """Change ``home_serve_share`` from the next serve on (a curriculum: defence first)."""
        unknown = sorted(set(options) - {"home_serve_share"})
        if unknown:
            raise ValueError(
                f"unknown serve option {unknown[0]!r}; keeper against keeper changes only "
                "home_serve_share"
            )
        if options:
            self.home_serve_share = check_share("home_serve_share", options["home_serve_share"])

    def sample_start(
        self,
        rng: np.random.Generator,
        ball_position=None,
        ball_velocity=None,
        options: dict[str, Any] | None = None,
    ) -> Start:
        team = table.HOME if rng.random() < self.home_serve_share else table.AWAY
        position = resting_in_front_of(rng, team)
        if ball_position is not None:
            position = ball_position
        velocity = (0.0, 0.0) if ball_velocity is None else ball_velocity
        return Start([0.0, 0.0], [0.0, 0.0], position, velocity)
