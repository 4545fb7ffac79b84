"""Rewards: the base terms of the paper, every term in info, the reward is their sum."""

from __future__ import annotations

import gymnasium as gym
import pytest

from foosball_gym import ENV_IDS
from foosball_gym.envs.rewards import TERMS


def test_conceding_a_goal_costs_the_goal_reward_and_ends_the_episode(make_env):
    env = make_env("Foosball-Block-v0")
    env.reset(options={"ball_position": (-0.3, -0.08), "ball_velocity": (-4.0, 0.0)})
    for _ in range(30):
        # Keeper pinned to the far side: the ball goes in.
        _, reward, terminated, _, info = env.step([1.0])
        if terminated:
            break
    assert terminated and info["goal"] == -1 and not info["is_success"]
    assert reward == pytest.approx(-1000.0)
    assert info["reward_goal"] == pytest.approx(-1000.0)


def test_goal_weight_is_a_constructor_argument(make_env):
    env = make_env("Foosball-Block-v0", goal_reward=5.0)
    env.reset(options={"ball_position": (-0.3, -0.08), "ball_velocity": (-4.0, 0.0)})
    for _ in range(30):
        _, reward, terminated, _, info = env.step([1.0])
        if terminated:
            break
    assert reward == pytest.approx(-5.0)


def test_ball_leaving_the_table_is_penalised_and_ends_the_episode(make_env):
    env = make_env("Foosball-Block-v0", out_of_table_penalty=300.0)
    env.reset(options={"ball_position": (0.2, 0.0), "ball_velocity": (0.0, 0.0)})
    # Throw the ball up through the simulator: nothing in the task does that on its own.
    sim = env.unwrapped.sim
    sim._p.resetBaseVelocity(sim.ball, [0.0, 0.0, 3.0], [0.0, 0.0, 0.0])
    for _ in range(30):
        _, reward, terminated, _, info = env.step([0.0])
        if terminated:
            break
    assert terminated and info["out_of_table"]
    assert reward == pytest.approx(-300.0) == info["reward_out_of_table"]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_reward_is_the_sum_of_the_terms_in_info(env_id):
    env = gym.make(
        env_id,
        ball_to_goal_weight=1.0,
        figurine_to_ball_weight=2.0,
        action_regularisation_weight=0.5,
    )
    try:
        env.reset(seed=1)
        seen_nonzero = set()
        for _ in range(60):
            _, reward, terminated, truncated, info = env.step(env.action_space.sample())
            parts = [info["reward_" + t] for t in TERMS]
            assert reward == pytest.approx(sum(parts))
            seen_nonzero |= {t for t in TERMS if info["reward_" + t] != 0}
            if terminated or truncated:
                env.reset()
        assert {"ball_to_goal", "figurine_to_ball", "action_regularisation"} <= seen_nonzero
    finally:
        env.close()
