"""Every registered id, with every combination of its options, passes both env checkers and
has the observation its docstring promises."""

from __future__ import annotations

import itertools

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from scripts_loader import load_script

from foosball_gym import ENV_IDS
from foosball_gym.registration import check_env_options


def grid_cases():
    for env_id in ENV_IDS:
        grid = gym.envs.registration.load_env_creator(gym.spec(env_id).entry_point).option_grid()
        for values in itertools.product(*grid.values()):
            yield pytest.param(
                env_id,
                dict(zip(grid, values)),
                id=f"{env_id}-" + "-".join(f"{k}={v}" for k, v in zip(grid, values)),
            )


@pytest.mark.parametrize("env_id, kwargs", list(grid_cases()))
def test_both_checkers_pass_for_every_option_combination(env_id, kwargs):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id, **kwargs)
    try:
        gym_check_env(env.unwrapped, skip_render_check=True)
        sb3_checker.check_env(env, warn=True)
        assert env.observation_space.shape == (len(env.unwrapped.obs_builder.names),)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_grid_names_every_discrete_option_of_the_constructor(env_id):
    """A new boolean or choice argument cannot be left out of the tested grid."""
    env = gym.make(env_id)
    cls, has_opponent = type(env.unwrapped), bool(env.unwrapped.layout.opponent)
    env.close()
    grid = cls.option_grid()
    defaults = cls.option_defaults()
    flags = {name for name, default in defaults.items() if isinstance(default, bool)}
    if not has_opponent:
        flags.discard("opponent_prismatic_only")  # rejected where there is no opponent
    assert flags <= set(grid)
    for name, values in grid.items():
        assert defaults[name] == values[0], name


@pytest.mark.parametrize(
    "env_id, kwargs, size",
    [
        ("Foosball-Block-v0", {}, 6),
        ("Foosball-Block-v0", {"joint_velocities": False}, 5),
        ("Foosball-Score-v0", {}, 8),
        ("Foosball-Score-v0", {"obstacles": True}, 11),
        ("Foosball-Score-v0", {"joint_velocities": False}, 6),
        ("Foosball-KeeperVsKeeper-v0", {}, 10),
        ("Foosball-KeeperVsKeeper-v0", {"opponent_prismatic_only": False}, 12),
        ("Foosball-FullGame-v0", {}, 36),
        ("Foosball-FullGame-v0", {"opponent_prismatic_only": True}, 28),
        ("Foosball-FullGame-v0", {"joint_velocities": False}, 20),
        ("Foosball-FullGame-v0", {"observe_figurines": True}, 4 * 11 * 2 + 4),
    ],
)
def test_observation_sizes_follow_the_options(env_id, kwargs, size):
    env = gym.make(env_id, **kwargs)
    try:
        assert env.observation_space.shape == (size,)
        assert env.reset(seed=0)[0].shape == (size,)
        # The check that builds nothing knows it too, and the action's.
        checked = check_env_options(env_id, kwargs)
        assert checked.observation_size == size
        assert (checked.action_size,) == env.action_space.shape
    finally:
        env.close()


def test_keeper_vs_keeper_layout_is_the_papers():
    env = gym.make("Foosball-KeeperVsKeeper-v0")
    try:
        assert env.unwrapped.obs_builder.names == (
            "home_keeper_slide_pos",
            "home_keeper_spin_pos",
            "home_keeper_slide_vel",
            "home_keeper_spin_vel",
            "away_keeper_slide_pos",
            "away_keeper_slide_vel",
            "ball_x",
            "ball_y",
            "ball_vx",
            "ball_vy",
        )
        assert env.action_space.shape == (2,)
    finally:
        env.close()


def test_score_obstacle_positions_are_appended_after_the_ball(make_env):
    env = make_env("Foosball-Score-v0", obstacles=True)
    obs, _ = env.reset(seed=0, options={"obstacle_positions": (0.1, -0.05, 0.02)})
    assert env.unwrapped.obs_builder.names[-3:] == (
        "away_keeper_slide_pos",
        "away_defense_slide_pos",
        "away_offense_slide_pos",
    )
    assert obs[-3:] == pytest.approx([0.1, -0.05, 0.02], abs=1e-6)
    for _ in range(30):  # they stay where they were put
        obs, *_ = env.step(env.action_space.sample())
    assert obs[-3:] == pytest.approx([0.1, -0.05, 0.02], abs=2e-3)


def straight_shot(env, **options) -> bool:
    """Whether a ball shot straight down the middle at the away goal goes in."""
    start = {"ball_position": (-0.40, 0.0), "ball_velocity": (4.0, 0.0)}
    env.reset(seed=0, options={**start, **options})
    while True:
        _, _, terminated, truncated, info = env.step([0.0, 0.0])
        if terminated or truncated:
            return bool(info["is_success"])


def test_obstacle_rods_not_standing_are_spun_up_and_let_the_ball_pass(make_env):
    centred = {"obstacle_positions": (0.0, 0.0, 0.0)}  # a figurine of each on the middle line
    standing = make_env("Foosball-Score-v0", obstacles=True)
    assert not straight_shot(standing, **centred)
    assert list(standing.unwrapped.game.positions[5:8]) == pytest.approx([0.0] * 3, abs=0.05)
    up = make_env("Foosball-Score-v0", obstacles=True, obstacle_share=0.0)
    assert straight_shot(up, **centred)
    # Held a quarter turn up the whole way, their slides observed as the standing rods' are.
    assert list(up.unwrapped.game.positions[5:8]) == pytest.approx([np.pi / 2] * 3, abs=0.05)
    assert up.unwrapped.obs_builder.names == standing.unwrapped.obs_builder.names


def test_each_obstacle_rod_stands_with_the_obstacle_share_and_all_do_by_default(make_env):
    env = make_env("Foosball-Score-v0", obstacles=True, obstacle_share=0.5)
    spins = []
    for seed in range(100):
        env.reset(seed=seed)
        spins += list(env.unwrapped.game.positions[5:8])
    standing = sum(abs(s) < 0.1 for s in spins)
    assert sum(abs(s - np.pi / 2) < 0.1 for s in spins) == 300 - standing
    assert 120 <= standing <= 180  # 300 rods at one chance in two: 150 ± 3.5 sigma
    # The default, 1, draws nothing more: the task's own episodes, seed for seed.
    default = make_env("Foosball-Score-v0", obstacles=True)
    every = make_env("Foosball-Score-v0", obstacles=True, obstacle_share=1.0)
    for seed in range(5):
        assert default.reset(seed=seed)[0] == pytest.approx(every.reset(seed=seed)[0])
        assert list(every.unwrapped.game.positions[5:8]) == [0.0] * 3


def test_a_shut_lane_share_of_one_shuts_every_straight_lane_and_none_is_the_default(make_env):
    straight_lane_open = load_script("shot_lanes").straight_lane_open
    env = make_env("Foosball-Score-v0", obstacles=True, shut_lane_share=1.0)
    names = list(env.unwrapped.obs_builder.names)
    assert not any(straight_lane_open(names, env.reset(seed=s)[0]) for s in range(40))
    # The default, 0, draws nothing more: the task's own balls, a third of them open.
    default = make_env("Foosball-Score-v0", obstacles=True)
    none = make_env("Foosball-Score-v0", obstacles=True, shut_lane_share=0.0)
    opened = 0
    for seed in range(40):
        obs = default.reset(seed=seed)[0]
        assert none.reset(seed=seed)[0] == pytest.approx(obs)
        opened += straight_lane_open(names, obs)
    assert 5 <= opened <= 25  # 36 % of 40: 14.6 ± 3.5 sigma
    # A ball and obstacles the user placed stay where they were put, its straight lane open.
    placed = {"ball_position": (-0.497, 0.0), "obstacle_positions": (0.06, 0.09, 0.06)}
    obs, _ = env.reset(seed=0, options=placed)
    assert obs[names.index("ball_y")] == pytest.approx(0.0, abs=1e-3)
    assert obs[-3:] == pytest.approx([0.06, 0.09, 0.06], abs=2e-3)
    assert straight_lane_open(names, obs)


def test_figurine_observation_follows_the_rod(make_env):
    env = make_env("Foosball-Block-v0", observe_figurines=True)
    obs, _ = env.reset(options={"ball_position": (0.3, 0.2), "ball_velocity": (0.0, 0.0)})
    names = env.unwrapped.obs_builder.names
    assert names[:4] == (
        "home_keeper_figurine_0_x",
        "home_keeper_figurine_0_y",
        "home_keeper_figurine_0_vx",
        "home_keeper_figurine_0_vy",
    )
    for _ in range(20):
        obs, *_ = env.step([0.5])
    assert obs[0] == pytest.approx(-0.522, abs=1e-3)
    assert obs[1] == pytest.approx(0.5 * 0.123, abs=2e-3)


@pytest.mark.parametrize(
    "env_id, kwargs, message",
    [
        ("Foosball-Score-v0", {"ball_start": "flying"}, "resting, incoming"),
        ("Foosball-Score-v0", {"obstacles": "yes"}, "True or False"),
        ("Foosball-Score-v0", {"obstacles": True, "obstacle_share": 1.5}, "obstacle_share"),
        ("Foosball-Score-v0", {"obstacle_share": 0.5}, "obstacle_share 0.5 needs obstacles=True"),
        ("Foosball-Score-v0", {"obstacles": True, "shut_lane_share": -0.1}, "shut_lane_share"),
        ("Foosball-Score-v0", {"shut_lane_share": 0.5}, "needs obstacles=True and ball_start"),
        (
            "Foosball-Score-v0",
            {"obstacles": True, "ball_start": "incoming", "shut_lane_share": 1.0},
            "ball_start='resting'",
        ),
        ("Foosball-Block-v0", {"opponent_prismatic_only": True}, "only to tasks with an opponent"),
        ("Foosball-FullGame-v0", {"continuous": 1}, "True or False"),
        ("Foosball-KeeperVsKeeper-v0", {"stagnation_steps": -1}, "non-negative"),
        ("Foosball-KeeperVsKeeper-v0", {"opponent": "builtin:keeper-vs-keeper"}, "callable"),
        ("Foosball-Score-v0", {"residual": -0.1}, r"residual must be a number in \[0, 2.0\]"),
        ("Foosball-Block-v0", {"residual": "much"}, "residual must be a number"),
        ("Foosball-Score-v0", {"residual": [0.5]}, "a list of 2 such numbers"),
        ("Foosball-Score-v0", {"residual": [0.5, 3.0]}, "a list of 2 such numbers"),
        ("Foosball-Score-v0", {"residual": [0.5, "x"]}, "a list of 2 such numbers"),
    ],
)
def test_invalid_arguments_say_what_is_allowed(env_id, kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make(env_id, **kwargs)
    # The check that builds no simulator says the same.
    with pytest.raises(ValueError, match=message):
        check_env_options(env_id, kwargs)


def test_bad_obstacle_positions_are_rejected(make_env):
    env = make_env("Foosball-Score-v0", obstacles=True)
    with pytest.raises(ValueError, match="three prismatic values"):
        env.reset(options={"obstacle_positions": (0.5, 0.0, 0.0)})
    plain = make_env("Foosball-Score-v0")
    with pytest.raises(ValueError, match="obstacles=True"):
        plain.reset(options={"obstacle_positions": (0.0, 0.0, 0.0)})


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_a_residual_policy_that_does_nothing_plays_the_scripted_baseline(env_id):
    """With ``residual``, action 0 is the baseline's move and a correction shifts it."""
    import numpy as np

    plain = gym.make(env_id)
    residual = gym.make(env_id, residual=0.2)
    baseline = plain.unwrapped.scripted_policy()
    n = residual.action_space.shape
    try:
        gym_check_env(residual.unwrapped, skip_render_check=True)
        obs_a, _ = plain.reset(seed=3)
        obs_b, _ = residual.reset(seed=3)
        for _ in range(60):
            obs_a, ra, ta, _, _ = plain.step(baseline(obs_a))
            obs_b, rb, tb, _, _ = residual.step(np.zeros(n, dtype=np.float32))
            np.testing.assert_array_equal(obs_a, obs_b)
            assert (ra, ta) == (rb, tb)
            if ta:
                break
        # A full correction moves the keeper where the baseline would not have.
        ends = []
        for sign in (1.0, -1.0):
            residual.reset(seed=3)
            for _ in range(10):
                obs, *_ = residual.step(np.full(n, sign, dtype=np.float32))
            ends.append(obs[0])
        assert abs(ends[0] - ends[1]) > 0.01
    finally:
        plain.close()
        residual.close()


def test_a_residual_scale_of_0_leaves_its_joint_to_the_baseline():
    """A scale for each entry of the action: the slides take the correction, the spins are
    exactly the baseline's whatever the policy gives there."""
    import numpy as np

    env_id = "Foosball-FullGame-v0"
    plain = gym.make(env_id)
    baseline = plain.unwrapped.scripted_policy()
    scales = [0.3, 0.0] * 4
    residual = gym.make(env_id, residual=scales)
    assert residual.unwrapped.residual == tuple(scales)
    assert gym.make(env_id, residual=[0.0] * 8).unwrapped.residual == 0.0
    rng = np.random.default_rng(0)
    try:
        obs, _ = residual.reset(seed=5)
        sent = []
        game = residual.unwrapped.game
        command = game.command
        game.command = lambda act: (sent.append(list(act)), command(act))[1]
        for _ in range(30):
            expected = np.asarray(baseline(obs), dtype=np.float64)
            correction = rng.uniform(-1, 1, 8).astype(np.float32)
            obs, *_ = residual.step(correction)
            spins, slides = np.asarray(sent[-1])[1::2], np.asarray(sent[-1])[0::2]
            np.testing.assert_array_equal(spins, expected[1::2])
            np.testing.assert_allclose(
                slides, np.clip(expected[0::2] + 0.3 * correction[0::2].astype(float), -1, 1)
            )
    finally:
        plain.close()
        residual.close()
