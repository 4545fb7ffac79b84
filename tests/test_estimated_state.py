"""Robust training: the policy sees the ball through a simulated camera and the real filter."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from foosball_gym import ENV_IDS
from foosball_gym.envs.estimated import CameraNoise, EstimatedState
from foosball_gym.registration import task_interface


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_estimated_state_passes_the_env_checkers(env_id):
    sb3_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env = gym.make(env_id, estimated_state=True)
    try:
        check_env(env.unwrapped, skip_render_check=True)
        sb3_checker.check_env(env)
    finally:
        env.close()


def test_the_estimate_follows_the_true_ball_closely_but_not_exactly(make_env):
    env = make_env("Foosball-Block-v0", estimated_state=True)
    obs, _ = env.reset(seed=2, options={"ball_position": (0.3, 0.1), "ball_velocity": (-2.0, -0.3)})
    errors = []
    for _ in range(15):
        obs, *_ = env.step([0.5])
        x, y, vx, vy = env.unwrapped.sim.ball_xy()
        errors.append((obs[2] - x, obs[3] - y, obs[4] - vx, obs[5] - vy))
    errors = np.abs(np.array(errors[5:]))
    assert errors[:, :2].max() < 0.025 and errors[:, 2:].max() < 0.8  # 2.5 cm, 0.8 m/s
    assert errors.max() > 0  # it is an estimate, not the truth
    # The keeper's own joints still come from its encoders, exactly.
    pos, vel = env.unwrapped.rod_joint_values()
    assert obs[0] == pytest.approx(pos[0], abs=1e-6)


def test_estimated_observations_are_seeded(make_env):
    a, b = (
        make_env("Foosball-Score-v0", estimated_state=True),
        make_env("Foosball-Score-v0", estimated_state=True),
    )
    for env in (a, b):
        env.reset(seed=11)
    for _ in range(20):
        oa, *_ = a.step(np.array([0.3, 0.1], np.float32))
        ob, *_ = b.step(np.array([0.3, 0.1], np.float32))
        np.testing.assert_array_equal(oa, ob)


def test_the_opponent_rod_is_estimated_from_noisy_measurements(make_env):
    env = make_env(
        "Foosball-KeeperVsKeeper-v0",
        estimated_state=True,
        opponent=lambda obs: np.array([0.5, 0.0]),
    )
    env.reset(seed=0)
    for _ in range(40):
        obs, *_ = env.step(np.zeros(2, np.float32))
    true_slide = env.unwrapped.rod_joint_values()[0][1]
    assert obs[4] == pytest.approx(true_slide, abs=0.015) and true_slide == pytest.approx(
        0.5 * 0.123, abs=2e-3
    )


def test_a_ball_under_a_figurine_head_is_not_seen():
    interface = task_interface("Foosball-Block-v0")
    state = EstimatedState(interface.builder, CameraNoise(drop_rate=0.0), np.random.default_rng(0))
    figurines = np.array([[-0.522, 0.05, 0.067]])
    seen, _ = state._measure(-0.522, 0.05, [0.05, 0.0], figurines)
    assert seen is None
    seen, _ = state._measure(-0.3, 0.05, [0.05, 0.0], figurines)
    assert seen is not None


def test_the_camera_runs_at_its_own_frame_rate_and_delivers_after_its_latency():
    interface = task_interface("Foosball-Block-v0")
    state = EstimatedState(
        interface.builder,
        CameraNoise(fps=90, latency_s=0.05, drop_rate=0.0),
        np.random.default_rng(0),
    )
    none = np.zeros((0, 3))
    state.reset((0.3, 0.0, -1.0, 0.0), [0.0, 0.0], none)
    updates = []
    original = state.estimator.update
    state.estimator.update = lambda t, *a: (updates.append(t), original(t, *a))
    for k in range(1, 7):  # 0.1 s of control steps
        x = 0.3 - k / 60
        state.advance(1 / 60, (x, 0.0, -1.0, 0.0), [0.0, 0.0], none)
    # 90 frames/s for 0.1 s, seen 50 ms after they were taken: the frames up to t = 0.05.
    assert np.allclose(updates, [k / 90 for k in range(1, 5)])


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"camera_noise": {"fps": 60}}, "needs estimated_state=True"),
        ({"estimated_state": True, "camera_noise": {"noise": 1}}, "allowed: drop_rate"),
        ({"estimated_state": True, "camera_noise": {"drop_rate": 1.5}}, "drop_rate"),
    ],
)
def test_bad_camera_settings_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        gym.make("Foosball-Block-v0", **kwargs)
