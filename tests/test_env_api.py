"""Every registered id passes Gymnasium's and SB3's checkers and behaves as a user expects."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

from foosball_gym import ENV_IDS, table
from foosball_gym.sim import TableSim


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_gymnasium_check_env_passes(env_id, display):
    env = gym.make(env_id)
    try:
        gym_check_env(env.unwrapped)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_sb3_check_env_passes(env_id):
    sb3_env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id)
    try:
        sb3_env_checker.check_env(env, warn=True)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_observation_is_float32_and_inside_the_space(env_id, make_env):
    env = make_env(env_id)
    obs, info = env.reset(seed=3)
    assert obs.dtype == np.float32 and env.observation_space.contains(obs)
    for _ in range(20):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert obs.dtype == np.float32 and env.observation_space.contains(obs)
        assert {"goal", "is_success"} <= set(info)
        if terminated or truncated:
            break


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_rgb_array_render_is_a_top_view_image(env_id, make_env):
    env = make_env(env_id, render_mode="rgb_array", render_width=160, render_height=90)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (90, 160, 3) and frame.dtype == np.uint8
    # The green field fills the middle of the picture.
    r, g, b = frame[45, 60].astype(int)
    assert g > r and g > b


@pytest.mark.parametrize("size", [(10**6, 180), (320, 5000), (0, 180), (320.5, 180)])
def test_the_simulator_refuses_an_image_size_beyond_4k_before_drawing(size):
    sim = TableSim(["home_keeper"])
    try:
        with pytest.raises(ValueError, match=r"must be a whole number of pixels in \[1, 4096\]"):
            sim.render(*size)
        assert sim._view is None  # no world was built to draw it
    finally:
        sim.close()


def test_human_render_opens_the_gui(display, make_env):
    env = make_env("Foosball-Block-v0", render_mode="human")
    env.reset(seed=0)
    env.step([0.5])
    assert env.render() is None


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_non_finite_actions_are_rejected(env_id, make_env):
    env = make_env(env_id)
    env.reset(seed=0)
    bad = np.zeros(env.action_space.shape, dtype=np.float32)
    for value in (math.nan, math.inf, -math.inf):
        bad[0] = value
        with pytest.raises(ValueError, match="finite"):
            env.step(bad)


def test_wrong_action_size_is_rejected(make_env):
    env = make_env("Foosball-Block-v0")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="1 value"):
        env.step([0.1, 0.2])


def test_unknown_render_mode_is_rejected():
    with pytest.raises(ValueError, match="rgb_array"), pytest.warns(UserWarning):
        gym.make("Foosball-Block-v0", render_mode="video")


def test_step_before_reset_is_an_error(make_env):
    env = make_env("Foosball-Block-v0").unwrapped
    with pytest.raises(gym.error.ResetNeeded):
        env.step([0.0])


def test_block_observation_is_keeper_then_ball_in_si_units(make_env):
    env = make_env("Foosball-Block-v0")
    obs, _ = env.reset(seed=0, options={"ball_position": (0.2, -0.1), "ball_velocity": (-3.0, 0.5)})
    assert env.unwrapped.obs_builder.names == (
        "home_keeper_slide_pos",
        "home_keeper_slide_vel",
        "ball_x",
        "ball_y",
        "ball_vx",
        "ball_vy",
    )
    np.testing.assert_allclose(obs, [0.0, 0.0, 0.2, -0.1, -3.0, 0.5], atol=1e-6)


def test_reset_options_place_the_ball_exactly(make_env):
    env = make_env("Foosball-Block-v0")
    obs, _ = env.reset(options={"ball_position": (0.35, 0.21)})
    assert obs[2:4] == pytest.approx([0.35, 0.21], abs=1e-6)
    # A position alone is still a shot at the home goal.
    assert obs[4] < 0
    x_goal = obs[2] + obs[4] * (-table.GOAL_LINE_X - obs[2]) / obs[4]
    y_goal = obs[3] + obs[5] * (x_goal - obs[2]) / obs[4]
    assert abs(y_goal) <= table.GOAL_HALF_WIDTH


@pytest.mark.parametrize(
    "options, message",
    [
        ({"ball_pos": (0, 0)}, "allowed: ball_position, ball_velocity"),
        ({"ball_position": (2.0, 0.0)}, "off the field"),
        ({"ball_position": (0.1,)}, "two numbers"),
        ({"ball_velocity": (math.nan, 0.0)}, "finite"),
        ({"ball_velocity": (250.0, 0.0)}, r"250 m/s; the table is built for balls up to 20 m/s"),
        ({"ball_velocity": (-15.0, 15.0)}, r"must be in \[0, 20\]"),
        ([("ball_position", (0.0, 0.0))], "must be a dict of option names to values, got list"),
        ([], "must be a dict"),
        ("ball_position", "must be a dict"),
    ],
)
def test_bad_reset_options_raise_a_clear_error(make_env, options, message):
    env = make_env("Foosball-Block-v0")
    with pytest.raises(ValueError, match=message):
        env.reset(options=options)


@pytest.mark.parametrize(
    "position, velocity",
    [
        ((0.3, 0.0), (0.0, 20.0)),  # at a side wall
        ((0.0, 0.25), (-20.0, 0.0)),  # at the end wall beside the goal
        ((0.0, 0.11), (-20.0, 0.0)),  # at a goal post
        ((0.3, 0.0), (-20.0 * math.cos(0.5), 20.0 * math.sin(0.5))),  # off a wall, then on
    ],
)
def test_a_ball_as_fast_as_the_table_is_built_for_stays_on_it(make_env, position, velocity):
    env = make_env("Foosball-Block-v0")
    obs, _ = env.reset(seed=0, options={"ball_position": position, "ball_velocity": velocity})
    assert math.hypot(obs[4], obs[5]) == pytest.approx(20.0, rel=1e-6)
    for _ in range(90):
        obs, _, terminated, truncated, info = env.step([1.0])  # the keeper out of the way
        assert not info["out_of_table"]
        if info["goal"]:
            assert abs(obs[3]) <= table.GOAL_HALF_WIDTH
            break
        x, y = abs(obs[2]), abs(obs[3])
        assert y <= table.FIELD_HALF_WIDTH
        assert x <= table.FIELD_HALF_LENGTH or y <= table.GOAL_HALF_WIDTH  # or in the mouth


def test_a_ball_against_an_obstacle_placed_by_hand_is_refused(make_env):
    env = make_env("Foosball-Score-v0", obstacles=True)
    defense = table.rod("away_defense")
    ball = (defense.x, defense.figurine_y(0.0)[0] + 0.01)
    with pytest.raises(ValueError, match="lies against a figurine of away_defense"):
        env.reset(options={"ball_position": ball, "obstacle_positions": (0.0, 0.0, 0.0)})
    # One gap from it is clear, and the obstacle stays where it was put.
    ball = (defense.x, defense.figurine_y(0.0)[0] + 0.037)
    env.reset(options={"ball_position": ball, "obstacle_positions": (0.0, 0.0, 0.0)})
    assert list(env.unwrapped.game.positions[1:4]) == [0.0, 0.0, 0.0]
    # Drawn by the task, an obstacle is slid beside the ball, as the keeper is.
    env.reset(seed=0, options={"ball_position": ball})


def test_block_episode_is_90_steps_unless_a_goal_ends_it(make_env):
    env = make_env("Foosball-Block-v0")
    assert env.spec.max_episode_steps == 90
    env.reset(options={"ball_position": (0.2, 0.3), "ball_velocity": (0.0, 0.0)})
    truncations = []
    for _ in range(90):
        _, _, terminated, truncated, info = env.step([0.0])
        assert not terminated
        assert info["is_success"] and info["goal"] == 0
        truncations.append(truncated)
    assert truncations == [False] * 89 + [True]


def test_render_fps_follows_the_control_step():
    env = gym.make("Foosball-Block-v0", physics_hz=480, control_hz=120)
    try:
        assert env.unwrapped.metadata["render_fps"] == 120
    finally:
        env.close()


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"speed_range": (5.0, 2.0)}, "speed_range"),
        ({"shaping": "squared"}, "difference, potential"),
        ({"goal_reward": math.nan}, "finite"),
        ({"joint_velocities": "yes"}, "True or False"),
        ({"control_hz": 0}, "control_hz must be a positive integer"),
        ({"physics_hz": 30}, "physics_hz .30. must be at least control_hz .60."),
        ({"physics_hz": 250}, "whole multiple of control_hz"),
        ({"physics_hz": 240.5}, "physics_hz must be a positive integer"),
        ({"rolling_resistance": -0.01}, r"rolling_resistance must be a number in \[0.0, 0.5\]"),
        ({"rolling_resistance": math.nan}, "rolling_resistance"),
        ({"contact_travel": 0.5}, "contact_travel must be a number in"),
        ({"rolling_resistance_range": (0.02, 0.01)}, "rolling_resistance_range"),
        ({"speed_range": (2.0, 25.0)}, r"speed_range must satisfy 0.001 <= low <= high <= 20"),
        ({"render_width": 10**6}, r"render_width must be a whole number of pixels in \[1, 4096\]"),
        ({"render_height": 0}, r"render_height must be a whole number of pixels in \[1, 4096\]"),
        ({"render_width": 320.0}, "render_width must be a whole number"),
    ],
)
def test_bad_constructor_arguments_raise_a_clear_error(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("Foosball-Block-v0", **kwargs)


def test_close_twice_is_safe():
    env = gym.make("Foosball-Block-v0")
    env.close()
    env.close()


@pytest.mark.parametrize("action", [["0.5"], np.array([0.5 + 0.1j]), "0.5", [None]])
def test_an_action_must_be_real_numbers(action):
    env = gym.make("Foosball-Block-v0")
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match="number"):
            env.step(action)
    finally:
        env.close()


def test_a_closed_env_says_so_on_step_and_reset():
    env = gym.make("Foosball-Block-v0")
    env.reset(seed=0)
    env.close()
    with pytest.raises(gym.error.ClosedEnvironmentError, match="closed"):
        env.step([0.0])
    with pytest.raises(gym.error.ClosedEnvironmentError, match="closed"):
        env.reset(seed=0)
