"""Every info an environment returns, from reset or step, has the same keys with values of the
same types: recorders of infos (Minari's DataCollector) need that, and users may read any key
at any step."""

from __future__ import annotations

import numpy as np
import pytest

from foosball_gym import ENV_IDS
from foosball_gym.envs.rewards import TERMS
from foosball_gym.registration import env_class

RANDOMISED = {
    "ball_friction_range": (0.05, 0.2),
    "ball_restitution_range": (0.3, 0.7),
    "ball_mass_range": (0.02, 0.025),
    "drive_gain_range": (0.8, 1.2),
    "rolling_resistance_range": (0.005, 0.02),
}


def structure(info: dict) -> dict:
    """Each key with the type of its value; a dict's own structure, an array's shape and
    dtype."""
    out = {}
    for key, value in info.items():
        if isinstance(value, dict):
            out[key] = structure(value)
        elif isinstance(value, np.ndarray):
            out[key] = (np.ndarray, value.shape, value.dtype)
        else:
            out[key] = type(value)
    return out


def option_cases():
    """Every id with its defaults, with each other value of each option of its grid in turn,
    with domain randomisation on, with residual actions, and with whole-number reward weights
    (a weight's type must not leak into the terms')."""
    for env_id in ENV_IDS:
        yield pytest.param(env_id, {}, id=f"{env_id}-defaults")
        for name, values in env_class(env_id).option_grid().items():
            for value in values[1:]:
                yield pytest.param(env_id, {name: value}, id=f"{env_id}-{name}={value}")
        yield pytest.param(env_id, RANDOMISED, id=f"{env_id}-randomised")
        yield pytest.param(env_id, {"residual": 0.5}, id=f"{env_id}-residual")
        weights = {"goal_reward": 10, "ball_to_goal_weight": 2, "action_regularisation_weight": 1}
        yield pytest.param(env_id, weights, id=f"{env_id}-whole-number-weights")


@pytest.mark.parametrize("env_id, kwargs", list(option_cases()))
def test_reset_and_step_infos_have_the_same_keys_and_types(env_id, kwargs, make_env):
    env = make_env(env_id, **kwargs)
    rng = np.random.default_rng(0)
    env.action_space.seed(0)
    _, info = env.reset(seed=0)
    expected = structure(info)
    assert {"goal", "is_success", "out_of_table", "stagnated"} <= set(info)
    assert {"reward_" + name for name in TERMS} <= set(info)
    assert ("goals_for" in info) == bool(env.unwrapped.layout.opponent)
    assert ("dynamics" in info) == (kwargs is RANDOMISED)
    for step in range(150):
        action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        _, _, terminated, truncated, info = env.step(action)
        assert structure(info) == expected, step
        if terminated or truncated:
            _, info = env.reset(seed=step)
            assert structure(info) == expected


@pytest.mark.parametrize("env_id", ENV_IDS)
@pytest.mark.parametrize("kwargs", [{}, RANDOMISED], ids=["fixed", "randomised"])
def test_the_last_step_of_an_episode_has_the_infos_keys_and_types(env_id, kwargs, make_env):
    env = make_env(env_id, stagnation_steps=5, **kwargs)
    _, info = env.reset(seed=1, options={"ball_position": (0.0, 0.25), "ball_velocity": (0, 0)})
    expected = structure(info)
    still = np.zeros(env.action_space.shape, np.float32)
    for _ in range(30):
        _, reward, terminated, _, last = env.step(still)
        if terminated:
            break
    assert terminated and last["stagnated"]
    assert structure(last) == expected


def test_reset_says_nothing_has_happened_yet(make_env):
    env = make_env("Foosball-KeeperVsKeeper-v0", **RANDOMISED)
    _, info = env.reset(seed=4)
    assert (info["goal"], info["goals_for"], info["goals_against"]) == (0, 0, 0)
    assert not info["out_of_table"] and not info["stagnated"] and not info["is_success"]
    assert all(info["reward_" + name] == 0.0 for name in TERMS)
    # The dynamics drawn at the reset hold for the whole episode, and each step says so.
    drawn = info["dynamics"]
    assert set(drawn) == {name.removesuffix("_range") for name in RANDOMISED}
    for _ in range(3):
        info = env.step(np.zeros(2, np.float32))[-1]
        assert info["dynamics"] == drawn
    info["dynamics"]["ball_mass"] = 1.0  # a user's change reaches no later info
    assert env.step(np.zeros(2, np.float32))[-1]["dynamics"] == drawn


def test_a_blocks_success_holds_at_reset_as_it_will_until_a_goal(make_env):
    env = make_env("Foosball-Block-v0")
    _, info = env.reset(seed=0)
    # Success is no goal conceded so far: true before the first step, as the old info said.
    assert info["is_success"] and "goals_for" not in info
