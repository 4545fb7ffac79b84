"""Two-player tasks: the opponent sees the mirrored game and can be swapped at any time."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

TWO_PLAYER = ("Foosball-KeeperVsKeeper-v0", "Foosball-FullGame-v0")


def play(env, position, velocity, steps):
    obs, _ = env.reset(seed=0, options={"ball_position": position, "ball_velocity": velocity})
    policy = env.unwrapped.scripted_policy()
    states = []
    for _ in range(steps):
        obs, _, terminated, _, _ = env.step(policy(obs))
        pos, _ = env.unwrapped.rod_joint_values()
        states.append((pos, env.unwrapped.sim.ball_xy()))
        if terminated:
            break
    return states


def test_same_scripted_policy_on_both_sides_of_a_mirrored_start_mirrors_the_game():
    env = gym.make("Foosball-KeeperVsKeeper-v0")
    try:
        a = play(env, (0.3, 0.05), (-2.0, 0.4), 150)
        b = play(env, (-0.3, -0.05), (2.0, -0.4), 150)
    finally:
        env.close()
    assert len(a) == len(b) == 150
    kicked = False
    for (pos_a, ball_a), (pos_b, ball_b) in zip(a, b):
        # [home slide, away slide, home spin, away spin]: home in one game is away in the other.
        np.testing.assert_allclose(pos_a, [pos_b[1], pos_b[0], pos_b[3], pos_b[2]], atol=1e-9)
        np.testing.assert_allclose(ball_a, [-v for v in ball_b], atol=1e-9)
        kicked |= abs(pos_a[2]) > 1.0
    assert kicked  # the mirrored game included a shot, not just waiting


@pytest.mark.parametrize("env_id", TWO_PLAYER)
def test_opponent_observation_is_the_home_observation_of_the_mirrored_state(env_id):
    env = gym.make(env_id)
    try:
        u = env.unwrapped
        rng = np.random.default_rng(0)
        obs_a, _ = env.reset(options={"ball_position": (0.2, -0.1), "ball_velocity": (1.0, 2.0)})
        for _ in range(5):
            env.step(rng.uniform(-1, 1, env.action_space.shape).astype(np.float32))
        seen_by_opponent = u.opponent_observation()
        pos, vel = u.rod_joint_values()
        n = len(u.layout.controlled)
        m = len(pos) // 2

        def swap(values):
            slides, spins = values[:m], values[m:]
            return slides[n:] + slides[:n] + spins[n:] + spins[:n]

        ball = u.sim.ball_xy()
        home_view = u.obs_builder.build(swap(pos), swap(vel), [-b for b in ball])
        np.testing.assert_array_equal(seen_by_opponent, home_view)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", TWO_PLAYER)
def test_set_opponent_swaps_the_policy_without_rebuilding(env_id):
    env = gym.make(env_id)
    try:
        u = env.unwrapped
        calls = []

        def lazy(obs):
            calls.append(obs.copy())
            return np.zeros(u.action_space.shape, dtype=np.float32)

        sim = u.sim
        u.set_opponent(lazy)
        env.reset(seed=1)
        env.step(env.action_space.sample())
        assert len(calls) == 1 and calls[0].shape == u.observation_space.shape
        assert u.sim is sim
        u.set_opponent(None)  # back to the scripted default
        assert u.opponent is not lazy
        env.step(env.action_space.sample())
        assert len(calls) == 1
    finally:
        env.close()


def test_an_opponent_passed_to_make_is_used():
    moves = []
    env = gym.make(
        "Foosball-KeeperVsKeeper-v0", opponent=lambda obs: moves.append(1) or np.array([1.0, 0.0])
    )
    try:
        env.reset(seed=0)
        for _ in range(20):
            env.step(np.zeros(2, dtype=np.float32))
        assert len(moves) == 20
        # The away keeper went to the far end of its rod, at +0.123 in its own frame.
        assert env.unwrapped.rod_joint_values()[0][1] == pytest.approx(0.123, abs=2e-3)
    finally:
        env.close()


def test_a_bad_opponent_action_is_reported():
    env = gym.make("Foosball-KeeperVsKeeper-v0", opponent=lambda obs: np.array([np.nan, 0.0]))
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError, match="opponent action must be finite"):
            env.step(np.zeros(2, dtype=np.float32))
    finally:
        env.close()


def test_single_player_tasks_have_no_opponent():
    env = gym.make("Foosball-Block-v0")
    try:
        with pytest.raises(ValueError, match="no opponent"):
            env.unwrapped.set_opponent(lambda obs: obs)
    finally:
        env.close()


@pytest.mark.parametrize("env_id", TWO_PLAYER)
def test_two_player_info_keeps_the_score(env_id):
    env = gym.make(env_id)
    try:
        _, info = env.reset(seed=0)
        assert info["goals_for"] == info["goals_against"] == 0
        # Roll the ball into the away goal past a keeper that steps aside (to world y < 0).
        n = env.action_space.shape[0]
        env.unwrapped.set_opponent(lambda obs: np.array([1.0] + [0.0] * (n - 1)))
        env.reset(options={"ball_position": (0.45, 0.07), "ball_velocity": (3.0, 0.0)})
        for _ in range(30):
            _, reward, terminated, _, info = env.step(np.zeros(env.action_space.shape, np.float32))
            if terminated:
                break
        assert info["goal"] == 1 and info["goals_for"] == 1 and info["is_success"]
        assert reward == pytest.approx(1000.0)
    finally:
        env.close()


def test_continuous_full_game_serves_again_and_keeps_score():
    env = gym.make(
        "Foosball-FullGame-v0", continuous=True, opponent=lambda obs: np.zeros(8, dtype=np.float32)
    )
    try:
        # Lift every home and away foot out of the way so the ball runs into the goal.
        up = np.array([0.0, -0.25] * 4, dtype=np.float32)
        env.unwrapped.set_opponent(lambda obs: up)
        env.reset(seed=0, options={"ball_position": (0.45, 0.07), "ball_velocity": (3.0, 0.0)})
        for _ in range(40):
            obs, reward, terminated, truncated, info = env.step(up)
            assert not terminated
            if info["goal"]:
                break
        assert info["goal"] == 1 and info["goals_for"] == 1
        # Served again from a side wall.
        assert abs(obs[-4]) < 0.05 and abs(abs(obs[-3]) - 0.3) < 0.05
    finally:
        env.close()


def test_stagnant_ball_ends_keeper_vs_keeper_as_a_draw():
    # Without the dead-ball rule (tests/test_match_rules.py), which would end it sooner.
    env = gym.make("Foosball-KeeperVsKeeper-v0", dead_ball_steps=0)
    try:
        env.reset(options={"ball_position": (0.0, 0.0), "ball_velocity": (0.0, 0.0)})
        for step in range(1, 200):  # noqa: B007  (the step that ended it is checked)
            _, reward, terminated, truncated, info = env.step(np.zeros(2, np.float32))
            if terminated:
                break
        assert info["stagnated"] and step == 60 and reward == 0.0
        assert info["goals_for"] == info["goals_against"] == 0
    finally:
        env.close()


def test_continuous_keeper_vs_keeper_serves_again_after_a_dead_ball_and_a_goal():
    env = gym.make("Foosball-KeeperVsKeeper-v0", continuous=True)
    try:
        up = np.array([0.0, -0.25], dtype=np.float32)
        env.unwrapped.set_opponent(lambda obs: up)
        env.reset(seed=0, options={"ball_position": (0.0, 0.0), "ball_velocity": (0.0, 0.0)})
        for step in range(1, 200):  # noqa: B007  (the step that served again is checked)
            obs, reward, terminated, truncated, info = env.step(up)
            assert not terminated
            if info["stagnated"]:
                break
        # A dead ball is not a draw: it is served again in front of a keeper. At rest between
        # the keepers, out of their reach, it is dead after dead_ball_steps.
        assert step == 30 and reward == 0.0
        assert abs(abs(obs[-4]) - 0.497) < 0.01 and obs[-2] == obs[-1] == 0.0
        env.unwrapped.game.sim.place_ball((0.45, 0.07), (3.0, 0.0))
        for _ in range(40):
            obs, reward, terminated, truncated, info = env.step(up)
            assert not terminated
            if info["goal"]:
                break
        assert info["goal"] == 1 and info["goals_for"] == 1 and info["is_success"]
        assert reward == pytest.approx(1000.0)
        # The score runs on and the ball is in play again.
        obs, _, terminated, _, info = env.step(up)
        assert not terminated and info["goals_for"] == 1 and info["goals_against"] == 0
        assert abs(abs(obs[-4]) - 0.497) < 0.01
    finally:
        env.close()


def test_continuous_keeper_vs_keeper_succeeds_on_being_ahead():
    task = gym.make("Foosball-KeeperVsKeeper-v0", continuous=True).unwrapped
    try:
        assert task.success(2, 1) and not task.success(1, 1) and not task.success(1, 2)
        single = gym.make("Foosball-KeeperVsKeeper-v0").unwrapped
        assert single.success(1, 1)
        single.close()
    finally:
        task.close()
