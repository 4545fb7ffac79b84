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
from foosball_gym.tasks.serves import Shots

# The fastest ball the simulated table is built for (m/s): real play's fastest shots, which
# it keeps out of figurines, walls and posts (SPEC: 15-20 m/s). Served balls and balls placed
# by hand are held to it.
MAX_BALL_SPEED = table.RESOLVED_SPEED
# A ball this close to a figurine's overall box (m, along y) counts as touching it at a start.
CLEARANCE = 0.002
# How far (m, along x) from a rod's axis a resting ball reaches a hanging figurine's box.
REACH_X = table.FIGURINE_SIZE[0] / 2 + table.BALL_RADIUS
# How far (m, along y) from a figurine's centre a resting ball starts clear of it.
GAP_Y = table.FIGURINE_SIZE[1] / 2 + table.BALL_RADIUS + CLEARANCE
# A figurine moved to GAP_Y beside the ball lands there give or take a rounding error; it is
# clear within this much (m) of it, or it would be moved to the same place again and again.
_ROUNDING = 1e-9


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


def check_ball_velocity(name: str, value: Any) -> tuple[float, float]:
    """A ball velocity no faster than the simulated table keeps physical, or a ValueError
    saying what is allowed."""
    vx, vy = check_pair(name, value)
    speed = math.hypot(vx, vy)
    if speed > MAX_BALL_SPEED:
        raise ValueError(
            f"option {name!r} = ({vx}, {vy}) is {speed:.4g} m/s; the table is built for balls "
            f"up to {MAX_BALL_SPEED:g} m/s: hypot(vx, vy) must be in [0, {MAX_BALL_SPEED:g}]"
        )
    return vx, vy


def figurine_at_ball(rod: table.Rod, slide: float, ball: tuple[float, float]) -> int | None:
    """The index of the first of ``rod``'s hanging figurines that a resting ball at ``ball``
    touches (within CLEARANCE) with the rod at ``slide``, or None where it touches none."""
    bx, by = ball
    if abs(bx - rod.x) >= REACH_X:
        return None
    for k, fig_y in enumerate(rod.figurine_y(slide)):
        if abs(fig_y - by) < GAP_Y - _ROUNDING:
            return k
    return None


def clear_of_ball(rod: table.Rod, slide: float, ball: tuple[float, float]) -> float:
    """A slide value near ``slide`` at which no figurine of ``rod`` touches the ball.

    Tasks put the ball at rest close to a rod; starting with a figurine inside the ball would
    throw it across the table on the first step. A touching figurine is slid just beside the
    ball, on its own side where the rod's range allows, else on the other; the figurines are
    further apart than two such gaps, so that leaves none touching (a test tries every rod).
    """
    for _ in rod.figurine_offsets:
        k = figurine_at_ball(rod, slide, ball)
        if k is None:
            break
        off, by = rod.figurine_offsets[k], ball[1]
        away = 1.0 if rod.figurine_y(slide)[k] - by >= 0.0 else -1.0
        for side in (away, -away):
            candidate = rod.direction * (by + side * GAP_Y) - off
            if abs(candidate) <= rod.slide_limit:
                slide = candidate
                break
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
    #: What the task serves from, where it serves shots (see :meth:`served_shots`).
    shots: Shots
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

    def served_shots(self) -> Shots | None:
        """The shots the task serves its episodes from, if it serves shots."""
        return None

    def serve_options(self) -> dict[str, Any]:
        """The options :meth:`set_serves` can change, by the names the environments take,
        with their values now: a curriculum moves them (empty where there are none)."""
        shots = self.served_shots()
        return {} if shots is None else shots.options()

    def set_serves(self, **options: Any) -> None:
        """Change serve options (``speed_range``, ``serve_x_range``, ...: those of
        ``serves.SERVE_FIELDS``) for the episodes from the next reset on.

        Raises:
            ValueError: the task serves no shots, or an option is unknown or out of range.
        """
        shots = self.served_shots()
        if shots is None:
            raise ValueError(
                f"{type(self).__name__.removesuffix('Task')} with these options serves no shots "
                "whose options could change (Block does, and Score with ball_start='incoming'; "
                "Score with obstacles=True changes only its obstacle_share and shut_lane_share, "
                "keeper against keeper its home_serve_share)"
            )
        self.shots = shots.changed(**options)

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
