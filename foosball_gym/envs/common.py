"""Pieces the task modules share: argument checking and ball serves."""

from __future__ import annotations

import math

import numpy as np

from foosball_gym import table as T
from foosball_gym.envs.observations import ObservationOptions
from foosball_gym.envs.rewards import RewardWeights

GOAL_MOUTH_HALF = T.GOAL_HALF_WIDTH - T.BALL_RADIUS


def _flag(name: str, value: object) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def make_weights(
    goal_reward: float,
    out_of_table_penalty: float,
    ball_to_goal_weight: float,
    figurine_to_ball_weight: float,
    action_regularisation_weight: float,
    shaping: str,
    gamma: float,
) -> RewardWeights:
    return RewardWeights(
        goal=goal_reward,
        out_of_table=out_of_table_penalty,
        ball_to_goal=ball_to_goal_weight,
        figurine_to_ball=figurine_to_ball_weight,
        action_regularisation=action_regularisation_weight,
        shaping=shaping,
        gamma=gamma,
    )


def make_options(
    joint_velocities: bool, opponent_prismatic_only: bool, observe_figurines: bool
) -> ObservationOptions:
    return ObservationOptions(
        joint_velocities=_flag("joint_velocities", joint_velocities),
        opponent_prismatic_only=_flag("opponent_prismatic_only", opponent_prismatic_only),
        observe_figurines=_flag("observe_figurines", observe_figurines),
    )


def check_range(name: str, value: tuple[float, float], low: float = 0.0) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (low, high), got {value!r}") from None
    if not (low <= lo <= hi and math.isfinite(hi)):
        raise ValueError(f"{name} must be (low, high) with {low} <= low <= high, got {value!r}")
    return lo, hi


def shot_at_goal(
    rng: np.random.Generator,
    position: tuple[float, float],
    speed_range: tuple[float, float],
    defender: str,
) -> tuple[float, float]:
    """Velocity of a shot from ``position`` at a uniform point of ``defender``'s goal mouth."""
    goal_x = -T.GOAL_LINE_X if defender == T.HOME else T.GOAL_LINE_X
    target_y = float(rng.uniform(-GOAL_MOUTH_HALF, GOAL_MOUTH_HALF))
    speed = float(rng.uniform(*speed_range))
    dx, dy = goal_x - position[0], target_y - position[1]
    norm = math.hypot(dx, dy)
    return speed * dx / norm, speed * dy / norm
