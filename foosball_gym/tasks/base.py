"""What a task is, with no simulator behind it: its rods, its serves and its goal.

A :class:`Task` holds only the task's own options. The game (:mod:`foosball_gym.game`) plays
it on a simulated table and the environment (:mod:`foosball_gym.envs`) puts a Gymnasium face
on the game; the real table needs only the task's :class:`~foosball_gym.policy_io.Layout`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from foosball_gym import table
from foosball_gym.policies.ladder import Level, Policy, level_of
from foosball_gym.policies.scripted import ScriptedTeam
from foosball_gym.policy_io.task import Layout


@dataclass
class Start:
    """An episode's first state; joint lists follow ``Layout.rods``."""

    slide: list[float]
    spin: list[float]
    ball_position: tuple[float, float]
    ball_velocity: tuple[float, float]


def check_pair(name: str, value: Any) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"option {name!r} must be two numbers (x, y), got {value!r}") from None
    if not (math.isfinite(x) and math.isfinite(y)):
        raise ValueError(f"option {name!r} must be finite, got {value!r}")
    return x, y


def check_ball_position(name: str, value: Any) -> tuple[float, float]:
    x, y = check_pair(name, value)
    if abs(x) > table.BALL_LIMIT_X or abs(y) > table.BALL_LIMIT_Y:
        raise ValueError(
            f"option {name!r} = ({x}, {y}) is off the field; the ball's centre must lie "
            f"within |x| <= {table.BALL_LIMIT_X:.5f}, |y| <= {table.BALL_LIMIT_Y:.5f} m"
        )
    return x, y


def clear_of_ball(rod: table.Rod, slide: float, ball: tuple[float, float]) -> float:
    """A slide value near ``slide`` at which no figurine of ``rod`` overlaps the ball.

    Tasks put the ball at rest close to a rod; starting with a figurine inside the ball would
    throw it across the table on the first step.
    """
    bx, by = ball
    reach_x = table.FIGURINE_SIZE[0] / 2 + table.BALL_RADIUS
    if abs(bx - rod.x) >= reach_x:
        return slide
    gap = table.FIGURINE_SIZE[1] / 2 + table.BALL_RADIUS + 0.002
    for off, fig_y in zip(rod.figurine_offsets, rod.figurine_y(slide)):
        if abs(fig_y - by) < gap:
            # Move the figurine just beside the ball, on whichever side stays within the limits.
            for side in (np.sign(fig_y - by) or 1.0, -(np.sign(fig_y - by) or 1.0)):
                candidate = rod.direction * (by + side * gap) - off
                if abs(candidate) <= rod.slide_limit:
                    return clear_of_ball(rod, candidate, ball)
    return slide


class Task:
    """A foosball task: subclasses set :attr:`layout` in ``__init__`` from their options.

    Its options are its constructor's keyword arguments; the environment that plays it takes
    them too, with the same names and defaults.

    Class attributes:
        reset_options: keys ``reset(options=...)`` accepts.
    """

    layout: Layout
    extras: tuple[str, ...] = ()
    reset_options: ClassVar[tuple[str, ...]] = ("ball_position", "ball_velocity")
    #: True where a goal (or a dead ball) re-serves instead of ending the episode.
    continues_after_goal: bool = False
    #: A ball still this many steps where no figurine in play can reach it is dead (0: never).
    dead_ball_steps: int = 0
    #: The game's scripted teams, weakest first (:mod:`foosball_gym.policies.ladder`); the
    #: last is its scripted baseline. Empty for a task with one scripted policy.
    ladder: ClassVar[tuple[Level, ...]] = ()

    def sample_start(
        self,
        rng: np.random.Generator,
        ball_position: tuple[float, float] | None = None,
        ball_velocity: tuple[float, float] | None = None,
        options: dict[str, Any] | None = None,
    ) -> Start:
        """A first state drawn with ``rng``; a given ball position or velocity is kept."""
        raise NotImplementedError

    def success(self, goals_for: int, goals_against: int) -> bool:
        """Whether the task is met with this score so far."""
        raise NotImplementedError

    def match_over(self, goals_for: int, goals_against: int) -> bool:
        """Whether a match that goes on after goals is decided by this score (a first-to-N
        match); a task that ends at its first goal never is."""
        return False

    def match_steps(self, control_hz: int) -> int | None:
        """The control steps a match that goes on after goals lasts, if the task sets its
        length (None: until the time limit)."""
        return None

    def scripted_policy(self, names: Sequence[str], precise_state: bool = True) -> Policy:
        """The scripted baseline for the learner's side, on observations with ``names``.

        ``precise_state``: the observation is the simulator's own state, not an estimate from a
        camera (``estimated_state``, a real or simulated table), so skills that need the ball's
        path to a millimetre may be used."""
        if self.ladder:
            return self.ladder[-1].make(names, self.layout.controlled, precise_state)
        return ScriptedTeam(names, self.layout.controlled, self.layout.joints)

    def scripted_level(
        self, level: int | None, names: Sequence[str], precise_state: bool = True
    ) -> Policy:
        """The scripted team of rung ``level`` of the task's ladder for the learner's side
        (None: its scripted baseline, the top), on observations with ``names``.

        Raises:
            ValueError: the task has no such level (the message names those it has).
        """
        if level is None:
            return self.scripted_policy(names, precise_state)
        game = type(self).__name__.removesuffix("Task")
        return level_of(self.ladder, level, game).make(names, self.layout.controlled, precise_state)
