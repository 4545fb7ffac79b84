"""Matches between two policies, or a policy and the scripted side, on seeded serves: what a
league and self-play's gate play (the game itself is :mod:`foosball_gym.game`'s).

Each pair plays ``games`` games, half with each side at home; game ``k`` is served with seed
``seed + k``, so that all pairs given the same seed meet the same serves. A game is won by the
side with more goals when it ends (the env's episode: its goals, its length, and its draw for
a still ball where the env has one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np

from foosball_gym.evaluation import start_episode

if TYPE_CHECKING:
    from foosball_gym.envs.base import FoosballEnv


@dataclass
class Player:
    """One side of the league: ``policy`` maps a (home-side) observation to an action; None
    is the environment's scripted side."""

    name: str
    policy: Callable[[np.ndarray], Any] | None
    generation: int | None = None
    timesteps: int | None = None


@dataclass
class PairResult:
    """What ``home`` and ``away`` (indices into the players) scored against each other."""

    a: int
    b: int
    wins: int = 0  # a's
    draws: int = 0
    losses: int = 0  # b's wins
    goals_a: int = 0
    goals_b: int = 0


class Arena:
    """One environment for the whole league: its opponent is swapped between games."""

    def __init__(self, env_id: str, env_kwargs: dict[str, Any]) -> None:
        self.env = gym.make(env_id, **env_kwargs)
        base = cast("FoosballEnv", self.env.unwrapped)
        if not getattr(base, "layout", None) or not base.layout.opponent:
            self.env.close()
            raise ValueError(f"{env_id} has no opponent: a league needs a two-player task")
        self.scripted = base.scripted_policy()
        self.observation_size = int(np.prod(base.observation_space.shape))

    def game(self, home: Player, away: Player, seed: int) -> tuple[int, int]:
        """Goals of ``home`` and ``away`` in one game served with ``seed``."""
        cast("FoosballEnv", self.env.unwrapped).set_opponent(away.policy)  # None: the scripted side
        policy = home.policy or self.scripted
        start_episode(home.policy, away.policy)
        obs, info = self.env.reset(seed=seed)
        done = False
        while not done:
            obs, _, terminated, truncated, info = self.env.step(policy(obs))
            done = terminated or truncated
        return int(info["goals_for"]), int(info["goals_against"])

    def close(self) -> None:
        self.env.close()


def play_pair(arena: Arena, a: Player, b: Player, games: int, seed: int) -> PairResult:
    """``a`` against ``b`` over ``games`` games, ``a`` at home in the even ones."""
    result = PairResult(-1, -1)
    for k in range(games):
        if k % 2 == 0:
            g_a, g_b = arena.game(a, b, seed + k)
        else:
            g_b, g_a = arena.game(b, a, seed + k)
        result.goals_a += g_a
        result.goals_b += g_b
        result.wins += g_a > g_b
        result.losses += g_b > g_a
        result.draws += g_a == g_b
    return result
