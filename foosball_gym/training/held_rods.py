"""Training games in which some of the learner's rods are held at the action 0, so that the
rods it drives explore beside teammates that do not (``rods_held_share``).

In the full game a team's exploration noise on its spins costs it most of its defence
(docs/results/full-game.md), and the action 0 is a team of its own: rods centred, feet down,
or with ``slide_around_ball`` a figurine of every rod under the ball. Each game holds a random
part of the rods there, after the random subsets of rods the authors' newest code trains on.
The policy is not told which rods are held; the evaluation and the shipped policy drive them
all.
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np


def check_rods_held_share(share: Any, n_rods: int, env_id: str) -> None:
    """Refuse a share that is not a number in [0, 1), or one given to a task whose learner
    drives a single rod (which is never held, as each game leaves the learner one)."""
    if isinstance(share, bool) or not isinstance(share, int | float) or not math.isfinite(share):
        raise ValueError(f"rods_held_share must be a number in [0, 1), got {share!r}")
    if not 0 <= share < 1:
        raise ValueError(
            f"rods_held_share is the chance that each of the learner's rods is held in a game, "
            f"in [0, 1) (0: none held), got {share!r}"
        )
    if share and n_rods < 2:
        raise ValueError(
            f"rods_held_share holds some of the learner's rods in each game, leaving it at least "
            f"one; {env_id}'s learner drives {n_rods} rod, so it needs 0"
        )


class HeldRodsWrapper(gym.ActionWrapper):
    """At each reset, holds each of the learner's rods with probability ``share`` (at least one
    left free), and sets their entries of every action to 0 until the next reset.

    The draw has a generator of its own, seeded by the reset's seed, so that the serves the
    environment draws are those of a run without it.
    """

    def __init__(self, env: gym.Env, share: float) -> None:
        super().__init__(env)
        joints = env.unwrapped.interface.action_joints  # type: ignore[attr-defined]
        self.rods = tuple(dict.fromkeys(rod for rod, _ in joints))
        check_rods_held_share(share, len(self.rods), str(env.spec.id if env.spec else env))
        self.share = share
        # Which rod each action entry drives, as an index into self.rods.
        self._entry_rod = np.array([self.rods.index(rod) for rod, _ in joints])
        self._rng = np.random.default_rng()
        self.held = np.zeros(len(self.rods), dtype=bool)
        self._held_entries: np.ndarray | None = None

    def reset(self, **kwargs: Any) -> tuple[Any, dict[str, Any]]:
        if kwargs.get("seed") is not None:
            self._rng = np.random.default_rng(kwargs["seed"])
        held = self._rng.random(len(self.rods)) < self.share
        if held.all():
            held[self._rng.integers(len(self.rods))] = False
        self.held = held
        # The entries to zero, found once a game rather than at every step.
        self._held_entries = held[self._entry_rod] if held.any() else None
        return self.env.reset(**kwargs)

    def action(self, action: Any) -> Any:
        if self._held_entries is None:
            return action
        action = np.array(action, dtype=np.float32)
        action[self._held_entries] = 0.0
        return action
