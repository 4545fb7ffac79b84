"""The scripted keeper: the task is solvable, and doing nothing is not enough."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym.policies.scripted import ScriptedKeeper, crossing_y, fold_into_walls


def block_rate(policy, episodes: int) -> float:
    env = gym.make("Foosball-Block-v0")
    blocked = 0
    try:
        for seed in range(episodes):
            obs, info = env.reset(seed=seed)
            done = False
            while not done:
                obs, _, terminated, truncated, info = env.step(policy(obs))
                done = terminated or truncated
            blocked += info["is_success"]
    finally:
        env.close()
    return blocked / episodes


def test_scripted_keeper_blocks_at_least_90_percent_of_500_shots():
    env = gym.make("Foosball-Block-v0")
    keeper = ScriptedKeeper(env.unwrapped.obs_builder.names)
    env.close()
    assert block_rate(keeper, 500) >= 0.90


def test_doing_nothing_blocks_far_fewer_shots():
    assert block_rate(lambda obs: np.zeros(1, dtype=np.float32), 200) < 0.6


def test_wall_bounce_prediction():
    wall = 0.34 - 0.01725
    assert fold_into_walls(0.1) == pytest.approx(0.1)
    assert fold_into_walls(wall + 0.05) == pytest.approx(wall - 0.05)
    assert fold_into_walls(-wall - 0.05) == pytest.approx(-wall + 0.05)
    assert fold_into_walls(3 * wall + 0.01) == pytest.approx(-wall + 0.01)
    # From (0.3, 0) at 45 degrees towards -x and +y: hits the wall and comes back.
    assert crossing_y(0.3, 0.0, -1.0, 1.0, -0.522) == pytest.approx(2 * wall - 0.822)
    assert crossing_y(0.3, 0.0, 1.0, 0.0, -0.522) is None


def test_scripted_keeper_names_what_it_misses():
    with pytest.raises(ValueError, match="ball_vx"):
        ScriptedKeeper(["ball_x", "ball_y"])
