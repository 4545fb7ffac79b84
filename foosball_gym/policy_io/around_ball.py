"""A player trained with the environment option ``slide_around_ball``, playing where the
environment reads slides over the rods' travel.

Such a player's slide action is a place in a band around the ball it observes. The environment
converts the learner's own actions; every other side of a game takes actions over the rods'
travel, as the scripted teams give them: the away side of a two-player task (self-play's
snapshots, ``foosball eval --opponent``), and both sides of the games a gate or a league plays
in an environment made without the option. There the player converts its own actions, from the
observation it was given, which is its side's own view: the mirrored one for the away side.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from foosball_gym.policy_io.task import TaskInterface


@dataclass(frozen=True)
class AroundBallPlayer:
    """``player`` (observations to actions whose slides are read around the ball by
    ``interface.slide_around_ball``) as a callable from one observation, or a batch, to actions
    over the rods' travel.

    Attributes:
        player: the trained player.
        interface: the task's interface as the player was trained (its band above 0).
    """

    player: Any
    interface: TaskInterface

    def __post_init__(self) -> None:
        if not self.interface.slide_around_ball:
            raise ValueError("an AroundBallPlayer needs an interface with slide_around_ball > 0")

    def __call__(self, obs: Any) -> np.ndarray:
        obs = np.asarray(obs)
        action = np.asarray(self.player(obs), dtype=np.float32)
        convert = self.interface.table_action
        if obs.ndim == 1:
            return np.asarray(convert(action.tolist(), obs), dtype=np.float32)
        return np.asarray([convert(a.tolist(), o) for a, o in zip(action, obs)], dtype=np.float32)

    def around(self, player: Any) -> AroundBallPlayer:
        """Another player (a copy of this one's, in NumPy say) converted with the same band."""
        return replace(self, player=player)

    # What evaluation and the league ask of a loaded policy, answered by the one inside.

    @property
    def observation_size(self) -> int | None:
        return getattr(self.player, "observation_size", None)

    @property
    def env_id(self) -> str | None:
        return getattr(self.player, "env_id", None)

    def reset(self) -> None:
        reset = getattr(self.player, "reset", None)
        if callable(reset):
            reset()
