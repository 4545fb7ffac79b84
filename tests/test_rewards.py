"""Rewards: the base terms of the paper, every term in info, the reward is their sum."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import ENV_IDS, table
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
    env.unwrapped.sim.place_ball((0.2, 0.0), (0.0, 0.0, 3.0))
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
        ball_aim_weight=3.0,
        action_regularisation_weight=0.5,
    )
    try:
        obs, _ = env.reset(seed=1)
        env.action_space.seed(1)
        # Half the steps scripted, so the ball is sure to be struck and move towards a goal.
        scripted = env.unwrapped.scripted_policy()
        seen_nonzero = set()
        for k in range(90):
            action = scripted(obs) if k % 2 else env.action_space.sample()
            obs, reward, terminated, truncated, info = env.step(action)
            parts = [info["reward_" + t] for t in TERMS]
            assert reward == pytest.approx(sum(parts))
            seen_nonzero |= {t for t in TERMS if info["reward_" + t] != 0}
            if terminated or truncated:
                env.reset()
        assert {"ball_to_goal", "figurine_to_ball", "action_regularisation"} <= seen_nonzero
    finally:
        env.close()


def test_ball_aim_potential_follows_the_path_to_the_goal_mouth():
    from foosball_gym.envs.rewards import ball_aim_potential

    line = table.GOAL_LINE_X
    mouth = table.GOAL_HALF_WIDTH - table.BALL_RADIUS
    half = table.FIELD_HALF_WIDTH - table.BALL_RADIUS
    # Straight at the middle, and along a path that crosses just inside a post.
    assert ball_aim_potential(-0.5, 0.0, 5.0, 0.0) == 1.0
    assert ball_aim_potential(line - 0.5, 0.0, 5.0, 5.0 * (mouth - 0.001) / 0.5) == 1.0
    # 5 cm beside the post: e^-1; the same miss reached off a side wall is judged alike.
    beside = ball_aim_potential(line - 0.5, 0.0, 5.0, 5.0 * (mouth + 0.05) / 0.5)
    assert beside == pytest.approx(math.exp(-1.0))
    # Off the +y wall: from y=0 the path rises half, then comes back down to the mouth + 5 cm.
    run = 0.8
    rise = half + (half - mouth - 0.05)
    assert ball_aim_potential(line - run, 0.0, 4.0, 4.0 * rise / run) == pytest.approx(beside)
    # A bank into the mouth is on target.
    rise = half + half  # off the wall and back to the middle
    assert ball_aim_potential(line - run, 0.0, 4.0, 4.0 * rise / run) == pytest.approx(1.0)
    # Not on its way: too slow, away from the goal, or past the line.
    assert ball_aim_potential(0.0, 0.0, 0.4, 0.0) == 0.0
    assert ball_aim_potential(0.0, 0.0, -5.0, 0.0) == 0.0
    assert ball_aim_potential(line + 0.01, 0.0, 5.0, 0.0) == 0.0


def test_ball_aim_rewards_a_shot_aimed_at_the_mouth():
    """Score from rest: a ball pushed at the mouth gains the aim term's weight at once."""
    env = gym.make("Foosball-Score-v0", ball_aim_weight=100.0, goal_reward=0.0)
    try:
        env.reset(options={"ball_position": (0.1, 0.0), "ball_velocity": (3.0, 0.0)})
        _, _, _, _, info = env.step([0.0, 0.0])
        # At reset the ball already heads for the mouth: no change, nothing rewarded.
        assert info["reward_ball_aim"] == pytest.approx(0.0, abs=1e-9)
        env.reset(options={"ball_position": (0.1, 0.0), "ball_velocity": (0.0, 0.0)})
        env.unwrapped.sim.place_ball((0.1, 0.0), (3.0, 0.0, 0.0))
        _, reward, _, _, info = env.step([0.0, 0.0])
        assert info["reward_ball_aim"] == pytest.approx(100.0)
    finally:
        env.close()


def test_ball_threat_is_the_aim_at_the_learners_own_goal_negated():
    from foosball_gym.envs.rewards import ball_aim_potential, ball_threat_potential

    line = table.GOAL_LINE_X
    assert ball_threat_potential(0.5, 0.0, -5.0, 0.0) == -1.0
    # Heading for the opponent's goal, or too slow, threatens nothing.
    assert ball_threat_potential(-0.5, 0.0, 5.0, 0.0) == 0.0
    assert ball_threat_potential(0.0, 0.0, -0.4, 0.0) == 0.0
    # Beside the mouth, a bounce off a side wall folded in: the aim turned about the centre.
    args = (line - 0.8, 0.05, 4.0, 2.0)
    mirrored = (-args[0], -args[1], -args[2], -args[3])
    assert 0.0 < ball_aim_potential(*args) < 1.0
    assert ball_threat_potential(*mirrored) == -ball_aim_potential(*args)


def test_ball_threat_rewards_a_shot_turned_away_from_the_learners_goal():
    """Keeper against keeper: a shot at the learner's mouth costs the weight, turning it away
    gains it back."""
    env = gym.make(
        "Foosball-KeeperVsKeeper-v0",
        ball_threat_weight=100.0,
        goal_reward=0.0,
        opponent="scripted:0",
    )
    try:
        env.reset(seed=0, options={"ball_position": (0.0, 0.0), "ball_velocity": (-3.0, 0.0)})
        _, _, _, _, info = env.step([0.0, 0.0])
        assert info["reward_ball_threat"] == pytest.approx(0.0, abs=1e-9)  # as at reset
        env.unwrapped.sim.place_ball((-0.1, 0.0), (3.0, 0.0, 0.0))
        _, reward, _, _, info = env.step([0.0, 0.0])
        assert info["reward_ball_threat"] == pytest.approx(100.0)
        assert reward == pytest.approx(100.0)
        env.unwrapped.sim.place_ball((0.1, 0.0), (-3.0, 0.0, 0.0))
        _, _, _, _, info = env.step([0.0, 0.0])
        assert info["reward_ball_threat"] == pytest.approx(-100.0)
    finally:
        env.close()


def test_ball_aim_with_lanes_counts_only_paths_past_the_figurines():
    from foosball_gym.envs.rewards import LANE_BLOCK, ball_aim_potential, lane_blockers

    keeper = table.rod("away_keeper")
    half = table.FIELD_HALF_WIDTH - table.BALL_RADIUS
    # The keeper's figurine on the straight path stops it; just aside, the lane is open.
    assert ball_aim_potential(-0.5, 0.0, 5.0, 0.0, [(keeper.x, (0.0,))]) == 0.0
    assert ball_aim_potential(-0.5, 0.0, 5.0, 0.0, [(keeper.x, (LANE_BLOCK - 1e-4,))]) == 0.0
    assert ball_aim_potential(-0.5, 0.0, 5.0, 0.0, [(keeper.x, (LANE_BLOCK + 1e-4,))]) == 1.0
    # Behind the ball, a figurine is in no one's way.
    assert ball_aim_potential(0.3, 0.0, 5.0, 0.0, [(0.2, (0.0,))]) == 1.0
    # A bank into the middle of the mouth is judged where its folded path crosses a rod: off
    # the +y wall, three quarters of the way it has risen 1.5 half widths, 0.5 back down.
    line, run, rise = table.GOAL_LINE_X, 0.8, 2 * half
    x0, rod_x = line - run, line - run / 4
    vy = 4.0 * rise / run
    assert ball_aim_potential(x0, 0.0, 4.0, vy, [(rod_x, (half / 2,))]) == 0.0
    assert ball_aim_potential(x0, 0.0, 4.0, vy, [(rod_x, (-half / 2,))]) == 1.0
    # A rod spun up holds its soles above the ball: it blocks nothing.
    down = lane_blockers([keeper], [0.0, 0.3])
    assert down == [(keeper.x, keeper.figurine_y(0.0))]
    assert lane_blockers([keeper], [0.0, 1.2]) == []


@pytest.mark.parametrize(
    ("obstacles", "aim", "lane"),
    [
        ((0.0, 0.0, 0.0), 1.0, 0.0),  # the offense's middle figurine is in the way
        ((0.08, 0.0, 0.092), 1.0, 1.0),  # every figurine beside the path
    ],
)
def test_the_ball_lane_looks_past_the_obstacles(obstacles, aim, lane):
    """Score with obstacles, the ball heading straight for the mouth: with potential-based
    shaping a step rewards w * (0.99 * phi' - phi), -1 % of the weight where phi = 1 stays 1."""
    env = gym.make(
        "Foosball-Score-v0",
        obstacles=True,
        ball_aim_weight=300.0,
        ball_lane_weight=100.0,
        shaping="potential",
        goal_reward=0.0,
    )
    try:
        env.reset(
            options={
                "ball_position": (-0.4, 0.0),
                "ball_velocity": (3.0, 0.0),
                "obstacle_positions": obstacles,
            }
        )
        _, reward, _, _, info = env.step([0.0, 0.0])
        assert info["reward_ball_aim"] == pytest.approx(-3.0 * aim, abs=0.05)
        assert info["reward_ball_lane"] == pytest.approx(-1.0 * lane, abs=0.02)
        assert reward == pytest.approx(sum(info["reward_" + name] for name in TERMS))
    finally:
        env.close()


def test_ball_to_goal_potential_is_one_in_the_goal_mouth_and_decays_with_distance():
    from foosball_gym.envs.rewards import ball_to_goal_potential

    assert ball_to_goal_potential(0.61725, 0.0) == pytest.approx(1.0)
    assert ball_to_goal_potential(0.61725, 0.08) == pytest.approx(1.0)  # within the mouth
    assert ball_to_goal_potential(0.0, 0.0) == pytest.approx(math.exp(-6 * 0.61725))
    assert ball_to_goal_potential(0.61725, 0.18525) == pytest.approx(math.exp(-6 * 0.1))


def test_figurine_to_ball_potential_is_zero_when_aligned():
    from foosball_gym.envs.rewards import figurine_to_ball_potential

    assert figurine_to_ball_potential(0.05, [[0.05]]) == pytest.approx(0.0)
    assert figurine_to_ball_potential(0.2, [[0.0], [0.1, 0.3]]) == pytest.approx(
        -(1 - (math.exp(-1.2) + math.exp(-0.6)) / 2)
    )


def shaped_episode(shaping, weights):
    env = gym.make(
        "Foosball-Score-v0",
        ball_start="incoming",
        shaping=shaping,
        gamma=0.9,
        action_regularisation_weight=0.0,
        **weights,
    )
    obs, _ = env.reset(seed=4)
    states, infos = [obs], []
    rng = np.random.default_rng(0)
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(
            rng.uniform(-1, 1, 2).astype(np.float32)
        )
        states.append(obs)
        infos.append(info)
        done = terminated or truncated
    env.close()
    return states, infos, terminated


@pytest.mark.parametrize("shaping, gamma", [("difference", 1.0), ("potential", 0.9)])
def test_ball_to_goal_shaping_follows_its_formula(shaping, gamma):
    from foosball_gym.envs.rewards import ball_to_goal_potential

    states, infos, terminated = shaped_episode(shaping, {"ball_to_goal_weight": 2.0})
    phi = [ball_to_goal_potential(float(s[4]), float(s[5])) for s in states]
    for k, info in enumerate(infos):
        last = terminated and k == len(infos) - 1 and shaping == "potential"
        expected = 2.0 * ((0.0 if last else gamma * phi[k + 1]) - phi[k])
        assert info["reward_ball_to_goal"] == pytest.approx(expected, abs=1e-5)


def test_difference_shaping_telescopes_over_an_episode():
    from foosball_gym.envs.rewards import figurine_to_ball_potential

    states, infos, _ = shaped_episode("difference", {"figurine_to_ball_weight": 3.0})
    total = sum(i["reward_figurine_to_ball"] for i in infos)

    def phi(s):
        return figurine_to_ball_potential(float(s[5]), [[float(s[0])]])

    assert total == pytest.approx(3.0 * (phi(states[-1]) - phi(states[0])), abs=1e-4)


def test_action_regularisation_penalises_changes_of_action():
    env = gym.make("Foosball-Score-v0", action_regularisation_weight=2.0)
    try:
        env.reset(seed=0)
        _, _, _, _, info = env.step(np.array([0.5, -0.5], np.float32))
        assert info["reward_action_regularisation"] == pytest.approx(-2.0 * 0.25, abs=1e-6)
        _, _, _, _, info = env.step(np.array([0.5, -0.5], np.float32))
        assert info["reward_action_regularisation"] == pytest.approx(0.0)
    finally:
        env.close()


@pytest.mark.parametrize(
    "env_id, expected",
    [
        (
            "Foosball-Block-v0",
            {"goal": 1000.0, "out_of_table": 1000.0, "action_regularisation": 0.0},
        ),
        (
            "Foosball-Score-v0",
            {"goal": 1000.0, "out_of_table": 1000.0, "action_regularisation": 0.5},
        ),
        ("Foosball-KeeperVsKeeper-v0", {"goal": 1000.0, "action_regularisation": 0.0}),
        ("Foosball-FullGame-v0", {"goal": 1000.0, "ball_to_goal": 0.0}),
    ],
)
def test_default_weights_are_the_papers(env_id, expected):
    env = gym.make(env_id)
    try:
        for name, value in expected.items():
            assert getattr(env.unwrapped.weights, name) == value
    finally:
        env.close()
