"""A configuration is checked as the environment checks it, and no simulator is built to do it:
training's start-up, a model's fit to an environment, the simulated table and a dataset's
recording refuse a bad option before any world exists."""

from __future__ import annotations

import numpy as np
import pytest

import foosball_gym.sim
from foosball_gym.registration import task_interface


@pytest.fixture
def no_world(monkeypatch):
    """Any simulator built from here on fails the test."""

    def refuse(*args, **kwargs):
        raise AssertionError("a simulator was built")

    monkeypatch.setattr(foosball_gym.sim.TableSim, "__init__", refuse)


def test_training_start_up_checks_the_options_and_reads_the_task_without_a_simulator(no_world):
    pytest.importorskip("stable_baselines3")
    from foosball_gym.training.config import TrainConfig

    config = TrainConfig(
        "Foosball-KeeperVsKeeper-v0",
        env_kwargs={"opponent_prismatic_only": False},
        selfplay_scripted_share=0.5,
        selfplay_scripted_levels=[0, 2],
    )
    config.check()
    assert config.self_play is True  # a two-player task, read from the checked options
    assert config.selfplay_scripted_levels == (0, 2)
    with pytest.raises(ValueError, match="residual must be a number"):
        TrainConfig("Foosball-Block-v0", env_kwargs={"residual": -1}).check()
    with pytest.raises(ValueError, match="has no opponent; self-play"):
        TrainConfig("Foosball-Score-v0", self_play=True).check()
    with pytest.raises(TypeError, match="did you mean 'ball_start'"):
        TrainConfig("Foosball-Score-v0", env_kwargs={"ball_strat": "incoming"}).check()


def test_a_models_fit_to_an_environment_is_checked_without_a_simulator(no_world):
    pytest.importorskip("stable_baselines3")
    from foosball_gym.training.loading import load_policy

    loaded = load_policy("builtin:block")
    loaded.check_env("Foosball-Block-v0", {"max_episode_steps": 200})  # gymnasium's own keyword
    with pytest.raises(ValueError, match="expects observations of size 6"):
        loaded.check_env("Foosball-Block-v0", {"joint_velocities": False})
    with pytest.raises(ValueError, match="whole multiple of control_hz"):
        loaded.check_env("Foosball-Block-v0", {"physics_hz": 250})


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"stagnation_steps": -1}, "non-negative"),
        ({"physics_hz": 250}, "whole multiple of control_hz"),
        ({"ball_mass_range": (0.0, 2.0)}, "ball_mass_range"),
        ({"camera_noise": {"drop_rate": 0.5}}, "needs estimated_state=True"),
    ],
)
def test_the_simulated_table_refuses_what_the_environment_refuses_before_building(
    no_world, kwargs, message
):
    pytest.importorskip("canopen")
    from foosball_gym.real_table.virtual.simulated_table import SimulatedTable, virtual_table_config

    env_id = "Foosball-Block-v0"
    config = virtual_table_config(task_interface(env_id))
    with pytest.raises(ValueError, match=message):
        SimulatedTable(env_id, kwargs, config)


def test_a_dataset_with_a_bad_option_is_refused_before_anything_is_written(tmp_path, no_world):
    pytest.importorskip("minari")
    from foosball_gym.datasets import record_dataset

    def still(obs):
        return np.zeros(1, np.float32)

    with pytest.raises(ValueError, match="gamma must lie in"):
        record_dataset(
            still, "Foosball-Block-v0", "foosball/x-v0", {"gamma": 2}, data_path=tmp_path
        )
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("model", ["scripted", "builtin:block"])
def test_foosball_play_builds_one_simulator_the_one_it_plays_on(monkeypatch, model):
    pytest.importorskip("canopen")
    if model.startswith("builtin:"):
        pytest.importorskip("stable_baselines3")
    from foosball_gym.cli import main

    built = []
    build = foosball_gym.sim.TableSim.__init__

    def counted(self, *args, **kwargs):
        built.append(args)
        build(self, *args, **kwargs)

    monkeypatch.setattr(foosball_gym.sim.TableSim, "__init__", counted)
    argv = ["play", model, "--env", "Foosball-Block-v0", "--table", "sim", "--episodes", "1"]
    # In lock-step: on simulated time, a busy machine trips no watchdog.
    assert main([*argv, "--lockstep", "--camera", "320x180", "--no-status"]) == 0
    assert len(built) == 1
