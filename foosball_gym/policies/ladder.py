"""The scripted ladders of the two games: teams from one that stands still to the strongest,
each beating the one below it (docs/results/ladder.md has their league).

A level is named ``scripted:N`` wherever a policy or an opponent is named (``foosball eval
--policy scripted:N`` or ``--opponent scripted:N``, ``foosball league --add scripted:N``,
``foosball play scripted:N``, ``env.unwrapped.set_opponent("scripted:N")``, the ``opponent``
option); plain ``scripted`` is the top of the ladder, which is also the games' default
opponent and scripted baseline. Level 0 stands still.

Every level acts on the home side's observation, and so also as the opponent on the mirrored
one (:mod:`foosball_gym.policies.scripted`). The attacking levels time their kicks by their
rods' joint values; on an observation without them (``observe_figurines=True``) they play as
the aiming level.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from foosball_gym.policies.attack import AttackingTeam
from foosball_gym.policies.scripted import ScriptedTeam

SCRIPTED = "scripted"
Policy = Callable[[np.ndarray], Any]


class StandStill:
    """Every rod centred, feet down, whatever happens.

    Args:
        n_actions: the size of the action.
    """

    def __init__(self, n_actions: int) -> None:
        self.n_actions = int(n_actions)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros(self.n_actions, dtype=np.float32)


@dataclass(frozen=True)
class Level:
    """One rung of a ladder.

    Attributes:
        name: a short name.
        description: what it does, in a sentence.
        make: builds it from the observation's entry names, the rods it plays (in action
            order) and whether the observation is the simulator's own state (``precise``).
    """

    name: str
    description: str
    make: Callable[[Sequence[str], Sequence[str], bool], Policy]


def _still(names: Sequence[str], rods: Sequence[str], precise: bool) -> Policy:
    return StandStill(2 * len(rods))


def _kicking(names: Sequence[str], rods: Sequence[str], precise: bool) -> Policy:
    return ScriptedTeam(names, rods, "both")


def _aiming(names: Sequence[str], rods: Sequence[str], precise: bool) -> Policy:
    return ScriptedTeam(names, rods, "both", aim=True)


def _sees_its_joints(names: Sequence[str], rods: Sequence[str]) -> bool:
    return all(f"{r}_{j}_pos" in names for r in rods for j in ("slide", "spin"))


def _attacking(names: Sequence[str], rods: Sequence[str], precise: bool) -> Policy:
    if not _sees_its_joints(names, rods):
        return _aiming(names, rods, precise)
    return AttackingTeam(names, rods, deflect=precise)


def _attacking_keeper(names: Sequence[str], rods: Sequence[str], precise: bool) -> Policy:
    if not _sees_its_joints(names, rods):
        return _aiming(names, rods, precise)
    return AttackingTeam(names, rods, deflect=precise, corner=True)


STILL = Level("still", "stands still: every rod centred, feet down", _still)
KICKING = Level(
    "kicking",
    "blocks where the ball will cross each rod and kicks balls in reach straight ahead "
    "(the scripted team before the ladder)",
    _kicking,
)
AIMING = Level(
    "aiming", "kicks past the figurines where they stand, with a corner of the foot", _aiming
)
ATTACKING = Level(
    "attacking",
    "shoots where no defender can reach in time, aims late, lifts its own rods ahead of a "
    "shot and deflects fast balls towards the goal",
    _attacking,
)

ATTACKING_KEEPER = Level(
    "attacking",
    "shoots where the other keeper cannot reach in time, or, where it follows the ball, into "
    "the corner beside its goal; feet down before a ball coming at it",
    _attacking_keeper,
)

FULL_GAME_LADDER: tuple[Level, ...] = (STILL, KICKING, AIMING, ATTACKING)
KEEPER_LADDER: tuple[Level, ...] = (STILL, KICKING, ATTACKING_KEEPER)


def parse_scripted(spec: str) -> int | None:
    """The level ``spec`` names: ``"scripted"`` is None (the top), ``"scripted:N"`` is N.

    Raises:
        ValueError: ``spec`` is neither.
    """
    head, sep, tail = str(spec).partition(":")
    if head != SCRIPTED:
        raise ValueError(f"{spec!r} names no scripted team; use 'scripted' or 'scripted:N'")
    if not sep:
        return None
    try:
        level = int(tail)
    except ValueError:
        raise ValueError(f"{spec!r}: the level after 'scripted:' must be a whole number") from None
    return level


def is_scripted(spec: Any) -> bool:
    """Whether ``spec`` names a scripted team (``"scripted"`` or ``"scripted:..."``)."""
    return isinstance(spec, str) and spec.partition(":")[0] == SCRIPTED


def level_of(ladder: Sequence[Level], level: int | None, game: str) -> Level:
    """The rung ``level`` of ``ladder`` (None: the top), with an error naming the levels there
    are."""
    if not ladder:
        raise ValueError(f"{game} has no scripted ladder: name its scripted policy as 'scripted'")
    if level is None:
        return ladder[-1]
    if not 0 <= level < len(ladder):
        raise ValueError(
            f"{game} has no scripted level {level}; its levels are "
            + ", ".join(f"scripted:{i} ({rung.name})" for i, rung in enumerate(ladder))
            + f", and 'scripted' is scripted:{len(ladder) - 1}"
        )
    return ladder[level]


def describe(ladder: Sequence[Level]) -> str:
    """The levels of ``ladder``, one a line."""
    return "\n".join(
        f"scripted:{i}  {rung.name}: {rung.description}" for i, rung in enumerate(ladder)
    )
