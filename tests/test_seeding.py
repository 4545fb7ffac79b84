"""Same seed and actions give the same episode; different seeds give different ones."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import ENV_IDS


def rollout(env: gym.Env, seed: int, steps: int = 40) -> np.ndarray:
    obs, _ = env.reset(seed=seed)
    actions = np.random.default_rng(seed).uniform(-1, 1, (steps, *env.action_space.shape))
    out = [obs]
    for a in actions:
        obs, reward, terminated, truncated, _ = env.step(a.astype(np.float32))
        out.append(np.append(obs, reward))
        if terminated or truncated:
            obs, _ = env.reset()
            out.append(obs)
    return np.concatenate(out)


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_same_seed_and_actions_give_identical_observations(env_id):
    a, b = gym.make(env_id), gym.make(env_id)
    try:
        np.testing.assert_array_equal(rollout(a, 7), rollout(b, 7))
    finally:
        a.close()
        b.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_a_used_env_repeats_a_fresh_one(env_id):
    """Reset must wipe everything: an env that already played matches a new one."""
    used, fresh = gym.make(env_id), gym.make(env_id)
    try:
        rollout(used, 99, steps=120)
        np.testing.assert_array_equal(rollout(used, 7), rollout(fresh, 7))
    finally:
        used.close()
        fresh.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_different_seeds_give_different_starts(env_id):
    env = gym.make(env_id)
    try:
        starts = {tuple(env.reset(seed=s)[0].round(6)) for s in range(10)}
        assert len(starts) == 10
    finally:
        env.close()
