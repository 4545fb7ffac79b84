"""Ball serves the tasks share, and the checks of their options."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from foosball_gym import table as T

SHOT_SPEED_LIMITS = (1e-3, 2 * T.BALL_MAX_SPEED)
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
    goal_x = -T.GOAL_LINE_X if defender == T.HOME else T.GOAL_LINE_X
    target_y = float(rng.uniform(-T.GOAL_MOUTH_HALF, T.GOAL_MOUTH_HALF))
    speed = float(rng.uniform(*speed_range))
    dx, dy = goal_x - position[0], target_y - position[1]
    norm = math.hypot(dx, dy)
    return speed * dx / norm, speed * dy / norm


def resting_in_front_of(rng: np.random.Generator, team: str) -> tuple[float, float]:
    """A ball position at rest in front of ``team``'s keeper."""
    x = REST_X + float(rng.uniform(-REST_X_JITTER, REST_X_JITTER))
    y = float(rng.uniform(-REST_Y, REST_Y))
    return (-x, y) if team == T.HOME else (x, y)


def random_shot_start(
    rng: np.random.Generator, speed_range: tuple[float, float], defender: str = T.HOME
) -> tuple[tuple[float, float], tuple[float, float]]:
    """Block's serve: from x ~ U(0, 0.4), y ~ U(-0.3, 0.3) at ``defender``'s goal."""
    position = (float(rng.uniform(0.0, 0.4)), float(rng.uniform(-0.3, 0.3)))
    if defender == T.AWAY:
        position = (-position[0], -position[1])
    return position, shot_at_goal(rng, position, speed_range, defender)
