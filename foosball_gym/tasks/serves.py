"""Ball serves the tasks share, and the checks of their options."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.tasks.base import MAX_BALL_SPEED

# A shot no faster than the table is built for.
SHOT_SPEED_LIMITS = (1e-3, MAX_BALL_SPEED)
# The spec's resting ball: 0.497 m from the centre line, +-5 mm, in front of a keeper.
REST_X, REST_X_JITTER, REST_Y = 0.497, 0.005, 0.1


def check_range(name: str, value: Any, low: float, high: float) -> tuple[float, float]:
    """A (low, high) pair within [low, high] bounds, or a ValueError saying what is allowed."""
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (low, high), got {value!r}") from None
    if not (low <= lo <= hi <= high):
        raise ValueError(f"{name} must satisfy {low} <= low <= high <= {high}, got {value!r}")
    return lo, hi


def check_choice(name: str, value: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise ValueError(f"unknown {name} {value!r}; allowed: {', '.join(allowed)}")
    return value


def shot_at_goal(
    rng: np.random.Generator,
    position: tuple[float, float],
    speed_range: tuple[float, float],
    defender: str,
) -> tuple[float, float]:
    """Velocity of a shot from ``position`` at a uniform point of ``defender``'s goal mouth."""
    goal_x = -table.GOAL_LINE_X if defender == table.HOME else table.GOAL_LINE_X
    target_y = float(rng.uniform(-table.GOAL_MOUTH_HALF, table.GOAL_MOUTH_HALF))
    speed = float(rng.uniform(*speed_range))
    dx, dy = goal_x - position[0], target_y - position[1]
    norm = math.hypot(dx, dy)
    return speed * dx / norm, speed * dy / norm


def resting_in_front_of(rng: np.random.Generator, team: str) -> tuple[float, float]:
    """A ball position at rest in front of ``team``'s keeper."""
    x = REST_X + float(rng.uniform(-REST_X_JITTER, REST_X_JITTER))
    y = float(rng.uniform(-REST_Y, REST_Y))
    return (-x, y) if team == table.HOME else (x, y)


# Steeper bank shots are not served: they hardly move towards the goal.
BANK_MAX_ANGLE = 70.0
# Bank shots bounce in front of this x (defender's frame): a bounce behind the keeper's rod
# would meet the end wall beside the goal, not the mouth.
BANK_LAST_BOUNCE_X = -0.45
# Bank shots meet the goal line a median 8.5 mm further towards their wall than this aim says,
# and within 2.2 cm of that for 90 % of them, 4 cm for 95 % (150 shots, keeper lifted): the
# bounce ends a little deeper than the wall, and a slow ball curls as its spin settles. So they
# are aimed at the middle of the mouth, allowing for the offset.
BANK_AIM_HALF = table.GOAL_MOUTH_HALF - 0.03
BANK_AIM_OFFSET = 0.0085
SERVE_X_LIMITS = (-0.1, table.BALL_LIMIT_X - 0.1)
SERVE_Y_LIMITS = (-table.BALL_LIMIT_Y, table.BALL_LIMIT_Y)


def check_share(name: str, value: Any) -> float:
    """A fraction in [0, 1], or a ValueError saying what is allowed."""
    try:
        share = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}") from None
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"{name} must be a number in [0, 1], got {value!r}")
    return share


@dataclass(frozen=True)
class Shots:
    """Shots at a goal: where they start, how fast they go, and how many bank off a wall.

    Positions are in the frame of a defender at the home goal (x = -0.617): ``x_range`` and
    ``y_range`` bound a uniform start, ``speed_range`` a uniform speed. A share ``bank_share``
    of the shots is aimed off a side wall (either, at random) at a uniform point of the middle
    of the goal mouth; the others go straight at a uniform point of all of it. With
    ``bank_share == 0`` the draws are those of the plain shot, so seeded serves stay what they
    were before banks existed.
    """

    speed_range: tuple[float, float] = (2.0, 7.0)
    x_range: tuple[float, float] = (0.0, 0.4)
    y_range: tuple[float, float] = (-0.3, 0.3)
    bank_share: float = 0.0

    @classmethod
    def checked(
        cls,
        speed_range: Any,
        x_range: Any,
        y_range: Any,
        bank_share: Any,
    ) -> Shots:
        """Shots from user options, or a ValueError naming the bad one and what is allowed."""
        return cls(
            check_range("speed_range", speed_range, *SHOT_SPEED_LIMITS),
            check_range("serve_x_range", x_range, *SERVE_X_LIMITS),
            check_range("serve_y_range", y_range, *SERVE_Y_LIMITS),
            check_share("bank_share", bank_share),
        )

    def start(
        self, rng: np.random.Generator, defender: str = table.HOME
    ) -> tuple[tuple[float, float], tuple[float, float]]:
        """A start position and the shot from it at ``defender``'s goal."""
        position = (float(rng.uniform(*self.x_range)), float(rng.uniform(*self.y_range)))
        if defender == table.AWAY:
            position = (-position[0], -position[1])
        return position, self.aim(rng, position, defender)

    def aim(
        self, rng: np.random.Generator, position: tuple[float, float], defender: str
    ) -> tuple[float, float]:
        """The velocity of a shot from ``position`` at ``defender``'s goal mouth."""
        if self.bank_share == 0.0 or rng.uniform() >= self.bank_share:
            return shot_at_goal(rng, position, self.speed_range, defender)
        side = 1.0 if rng.uniform() < 0.5 else -1.0
        target_y = float(rng.uniform(-BANK_AIM_HALF, BANK_AIM_HALF))
        speed = float(rng.uniform(*self.speed_range))
        flip = 1.0 if defender == table.HOME else -1.0
        x, y = flip * position[0], flip * position[1]
        slope = bank_slope(x, y, target_y - side * BANK_AIM_OFFSET, side)
        if slope is None:
            side = -side  # that wall needs too steep a shot: bank off the other
            slope = bank_slope(x, y, target_y - side * BANK_AIM_OFFSET, side)
        if slope is None:
            return shot_at_goal(rng, position, self.speed_range, defender)
        norm = math.hypot(1.0, slope)
        return flip * -speed / norm, flip * side * speed * slope / norm


def bank_slope(x: float, y: float, target_y: float, side: float) -> float | None:
    """|vy| / |vx| of a shot from (x, y) that meets the home goal line at ``target_y`` after
    one bounce off the side wall at ``side`` (+1 or -1); None where that takes a shot steeper
    than BANK_MAX_ANGLE or a bounce behind BANK_LAST_BOUNCE_X."""
    wall = side * table.BALL_LIMIT_Y
    run = x + table.GOAL_LINE_X
    to_wall, from_wall = abs(wall - y), abs(wall - target_y)

    def short(slope: float) -> float:
        # How far short of the goal line (along x) the path at ``slope`` meets target_y.
        return run - to_wall / slope - from_wall / (table.wall_bounce_slope_ratio(slope) * slope)

    low, high = 1e-3, math.tan(math.radians(BANK_MAX_ANGLE))
    if short(high) < 0.0:
        return None
    for _ in range(40):  # the shortfall grows with the slope: bisect
        mid = 0.5 * (low + high)
        low, high = (low, mid) if short(mid) >= 0.0 else (mid, high)
    if x - to_wall / high < BANK_LAST_BOUNCE_X:
        return None
    return high
