"""A curriculum over serves: the environments' serves change between episodes, and a run
moves them from easy ones to its own over its first steps, resumed or not."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from scripts_loader import load_script

import foosball_gym  # noqa: F401  (registers the environments)
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.curriculum import serves_at


def served_speeds(env: gym.Env, episodes: int) -> list[float]:
    speeds = []
    for seed in range(episodes):
        obs, _ = env.reset(seed=seed)
        speeds.append(math.hypot(obs[-2], obs[-1]))
    return speeds


def test_set_serves_changes_the_shots_from_the_next_reset_on():
    env = gym.make("Foosball-Score-v0", ball_start="incoming")
    try:
        assert min(served_speeds(env, 20)) > 2.9
        env.unwrapped.set_serves(speed_range=(1.0, 1.2))
        assert all(0.99 < s < 1.21 for s in served_speeds(env, 20))
        env.unwrapped.set_serves(speed_range=(3.0, 7.0), serve_y_range=(0.2, 0.3))
        for seed in range(10):
            obs, _ = env.reset(seed=seed)
            assert 0.2 <= obs[-3] <= 0.3
    finally:
        env.close()


@pytest.mark.parametrize(
    "env_id, kwargs, options, message",
    [
        ("Foosball-Score-v0", {}, {"speed_range": (1, 2)}, "serves no shots"),
        ("Foosball-FullGame-v0", {}, {"speed_range": (1, 2)}, "serves no shots"),
        (
            "Foosball-KeeperVsKeeper-v0",
            {},
            {"speed_range": (1, 2)},
            "unknown serve option 'speed_range'; keeper against keeper changes only home_serve",
        ),
        (
            "Foosball-KeeperVsKeeper-v0",
            {},
            {"home_serve_share": 1.5},
            r"home_serve_share must be a number in \[0, 1\]",
        ),
        ("Foosball-Block-v0", {}, {"speeds": (1, 2)}, "unknown serve option 'speeds'.*speed_range"),
        ("Foosball-Block-v0", {}, {"speed_range": (3, 2)}, "speed_range must satisfy"),
        ("Foosball-Block-v0", {}, {"bank_share": 2}, "bank_share must be a number in"),
    ],
)
def test_serves_that_cannot_change_are_refused(env_id, kwargs, options, message):
    env = gym.make(env_id, **kwargs)
    try:
        with pytest.raises(ValueError, match=message):
            env.unwrapped.set_serves(**options)
    finally:
        env.close()


def standing_obstacles(env: gym.Env, episodes: int) -> int:
    """How many obstacle rods stood in the ball's way over ``episodes`` resets."""
    spins = []
    for seed in range(episodes):
        env.reset(seed=seed)
        spins += list(env.unwrapped.game.positions[5:8])  # the three obstacle rods' spins
    return sum(abs(s) < 0.1 for s in spins)


def test_the_obstacle_share_changes_from_the_next_reset_on():
    env = gym.make("Foosball-Score-v0", obstacles=True)
    try:
        assert standing_obstacles(env, 5) == 15
        env.unwrapped.set_serves(obstacle_share=0.0)
        assert standing_obstacles(env, 5) == 0
        with pytest.raises(ValueError, match=r"obstacle_share must be a number in \[0, 1\]"):
            env.unwrapped.set_serves(obstacle_share=2.0)
        # Nothing changes where an option is refused.
        with pytest.raises(ValueError, match="serves no shots"):
            env.unwrapped.set_serves(obstacle_share=1.0, speed_range=(1, 2))
        assert standing_obstacles(env, 5) == 0
    finally:
        env.close()
    plain = gym.make("Foosball-Score-v0")
    try:
        with pytest.raises(ValueError, match="obstacle_share needs obstacles=True"):
            plain.unwrapped.set_serves(obstacle_share=0.5)
    finally:
        plain.close()


def home_serves(env: gym.Env, episodes: int) -> int:
    """How many of ``episodes`` serves lay before the learner's keeper (x < 0)."""
    return sum(env.reset(seed=seed)[0][-4] < 0 for seed in range(episodes))


def test_the_keepers_serve_share_changes_from_the_next_reset_on():
    env = gym.make("Foosball-KeeperVsKeeper-v0")
    try:
        assert env.unwrapped.task.serve_options() == {"home_serve_share": 0.5}
        env.unwrapped.set_serves(home_serve_share=0.0)
        assert home_serves(env, 10) == 0
        env.unwrapped.set_serves(home_serve_share=1.0)
        assert home_serves(env, 10) == 10
    finally:
        env.close()


def test_a_curriculum_from_defence_alone_ends_at_the_runs_own_share():
    from foosball_gym.training.curriculum import run_serves

    config = TrainConfig(
        "Foosball-KeeperVsKeeper-v0",
        {"opponent": "scripted:1"},
        self_play=False,
        curriculum={"home_serve_share": 0.0},
        curriculum_steps=10,
    )
    config.check()
    assert run_serves("Foosball-KeeperVsKeeper-v0", {}, ["home_serve_share"]) == {
        "home_serve_share": 0.5
    }


def test_a_curriculum_over_the_obstacles_ends_at_the_runs_own_share():
    from foosball_gym.training.curriculum import run_serves

    kwargs = {"obstacles": True, "obstacle_share": 0.8}
    config = TrainConfig(
        "Foosball-Score-v0", kwargs, curriculum={"obstacle_share": 0.0}, curriculum_steps=10
    )
    config.check()
    assert run_serves("Foosball-Score-v0", kwargs, ["obstacle_share"]) == {"obstacle_share": 0.8}
    for start, message in [
        ({"obstacle_share": [0, 1]}, "a number"),
        ({"obstacle_share": -0.5}, "obstacle_share must be a number in"),
        ({"speed_range": [1, 2]}, "unknown serve option 'speed_range'; allowed here: obstacle_"),
    ]:
        config = TrainConfig("Foosball-Score-v0", kwargs, curriculum=start, curriculum_steps=10)
        with pytest.raises(ValueError, match=message):
            config.check()


def test_a_curriculum_over_shut_lanes_ends_at_the_tasks_own_balls():
    from foosball_gym.training.curriculum import run_serves

    kwargs = {"obstacles": True}
    config = TrainConfig(
        "Foosball-Score-v0", kwargs, curriculum={"shut_lane_share": 1.0}, curriculum_steps=10
    )
    config.check()
    assert run_serves("Foosball-Score-v0", kwargs, ["shut_lane_share"]) == {"shut_lane_share": 0.0}
    incoming = {"obstacles": True, "ball_start": "incoming"}
    config = TrainConfig(
        "Foosball-Score-v0", incoming, curriculum={"shut_lane_share": 1.0}, curriculum_steps=10
    )
    with pytest.raises(ValueError, match="unknown serve option 'shut_lane_share'"):
        config.check()


def test_the_shut_lane_share_changes_from_the_next_reset_on():
    lanes = load_script("shot_lanes")
    env = gym.make("Foosball-Score-v0", obstacles=True)
    names = list(env.unwrapped.obs_builder.names)
    env.unwrapped.set_serves(shut_lane_share=1.0)
    assert not any(lanes.straight_lane_open(names, env.reset(seed=s)[0]) for s in range(30))
    with pytest.raises(ValueError, match="shut_lane_share must be a number in"):
        env.unwrapped.set_serves(shut_lane_share=2.0)
    env.unwrapped.set_serves(shut_lane_share=0.0)
    assert any(lanes.straight_lane_open(names, env.reset(seed=s)[0]) for s in range(30))
    env.close()


def test_the_serves_move_in_a_straight_line_and_then_stay():
    start = {"speed_range": (1.0, 2.0), "bank_share": 0.0}
    end = {"speed_range": (3.0, 7.0), "bank_share": 0.5}
    assert serves_at(start, end, 0.0) == {"speed_range": (1.0, 2.0), "bank_share": 0.0}
    assert serves_at(start, end, 0.5) == {"speed_range": (2.0, 4.5), "bank_share": 0.25}
    assert serves_at(start, end, 3.0) == end


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"curriculum": {"speed_range": [1, 2]}}, "needs both"),
        ({"curriculum_steps": 1000}, "needs both"),
        ({"curriculum": {"speed_range": [1, 2]}, "curriculum_steps": -5}, "0 or more"),
        ({"curriculum": {"speeds": [1, 2]}, "curriculum_steps": 10}, "unknown serve option"),
        ({"curriculum": {"speed_range": 1.0}, "curriculum_steps": 10}, "a pair"),
        ({"curriculum": {"speed_range": [0, 1]}, "curriculum_steps": 10}, "speed_range must"),
        ({"curriculum": [1, 2], "curriculum_steps": 10}, "must map serve options"),
    ],
)
def test_a_curriculum_the_run_cannot_follow_is_refused_before_it_starts(settings, message):
    config = TrainConfig("Foosball-Score-v0", {"ball_start": "incoming"}, **settings)
    with pytest.raises(ValueError, match=message):
        config.check()


def test_a_curriculum_needs_a_task_that_serves_shots():
    for env_id, kwargs in [("Foosball-Score-v0", {}), ("Foosball-FullGame-v0", {})]:
        config = TrainConfig(
            env_id, kwargs, curriculum={"speed_range": [1, 2]}, curriculum_steps=10
        )
        with pytest.raises(ValueError, match="serves no shots"):
            config.check()


def test_a_run_follows_its_curriculum_and_a_resumed_run_goes_on_where_it_was(tmp_path):
    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.callbacks import BaseCallback

    from foosball_gym.training.sb3.trainer import train

    class ServedSpeeds(BaseCallback):
        """The speeds of the balls each rollout's environments were served, by step."""

        def __init__(self) -> None:
            super().__init__()
            self.speeds: dict[int, list[float]] = {}
            self._rollout = 0

        def _on_rollout_start(self) -> None:
            self._rollout = self.num_timesteps

        def _on_step(self) -> bool:
            for obs, done in zip(self.locals["new_obs"], self.locals["dones"]):
                if done:
                    raw = self.model.get_vec_normalize_env().unnormalize_obs(obs)
                    self.speeds.setdefault(self._rollout, []).append(float(np.hypot(*raw[-2:])))
            return True

    config = TrainConfig(
        "Foosball-Block-v0",
        timesteps=2048,
        n_envs=4,
        n_steps=128,
        batch_size=256,
        n_epochs=1,
        eval_freq=100_000,
        eval_episodes=2,
        checkpoint_freq=512,
        curriculum={"speed_range": [1.0, 1.0]},
        curriculum_steps=1024,
        lr_schedule="constant",
    )
    seen = ServedSpeeds()
    train(config, tmp_path / "run", callbacks=[seen])
    first, last = seen.speeds[0], seen.speeds[max(seen.speeds)]
    assert all(abs(s - 1.0) < 1e-6 for s in first)
    # Past curriculum_steps, the task's own serves: Block's 2-7 m/s.
    assert all(s > 1.99 for s in last)
    middle = seen.speeds[512]
    assert all(1.5 - 1e-6 <= s <= 4.0 + 1e-6 for s in middle)

    # Stopped at 600 steps, its last checkpoint at 512: resumed, its serves go on from
    # halfway, (1.5, 4.0) m/s, and not from the start.
    class StopAt(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps >= 600:
                raise KeyboardInterrupt
            return True

    with pytest.raises(KeyboardInterrupt):
        train(config, tmp_path / "stopped", callbacks=[StopAt()])
    resumed = ServedSpeeds()
    train(config, tmp_path / "stopped", resume=True, callbacks=[resumed])
    again = resumed.speeds[512]
    assert all(1.5 - 1e-6 <= s <= 4.0 + 1e-6 for s in again)
    assert max(again) > 1.01
