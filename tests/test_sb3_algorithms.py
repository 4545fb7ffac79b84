"""A model of any SB3 or sb3-contrib algorithm that acts on continuous actions loads and acts as
in its own library, and ``foosball eval`` rates it; what cannot load is refused in one line."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("sb3_contrib")

import sb3_contrib  # noqa: E402
import stable_baselines3 as sb3  # noqa: E402
import torch as th  # noqa: E402
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.evaluation import evaluate  # noqa: E402
from foosball_gym.training.loading import (  # noqa: E402
    LoadedPolicy,
    ModelLoadError,
    UnknownPhysicsWarning,
    load_policy,
)

ENV_ID = "Foosball-Block-v0"
OFF_POLICY = {"learning_starts": 100, "batch_size": 32, "train_freq": 4}
# Small networks and a couple of hundred steps: enough to hold weights of their own that are
# no network's defaults, fast enough for the default run.
ALGORITHMS = {
    "PPO": (sb3.PPO, {"n_steps": 64, "batch_size": 64, "n_epochs": 1}),
    "A2C": (sb3.A2C, {"n_steps": 16}),
    "SAC": (sb3.SAC, OFF_POLICY),
    "TD3": (sb3.TD3, OFF_POLICY),
    "DDPG": (sb3.DDPG, OFF_POLICY),
    "TQC": (sb3_contrib.TQC, {**OFF_POLICY, "policy_kwargs": {"n_quantiles": 5}}),
    "ARS": (sb3_contrib.ARS, {"n_delta": 2, "n_eval_episodes": 1}),
    "ARS-MLP": (sb3_contrib.ARS, {"n_delta": 2, "n_eval_episodes": 1, "policy": "MlpPolicy"}),
    "TRPO": (sb3_contrib.TRPO, {"n_steps": 64, "batch_size": 64}),
    "CrossQ": (sb3_contrib.CrossQ, OFF_POLICY),
    # Settings the defaults would get wrong: ReLU, separate heads, state-dependent noise.
    "PPO-ReLU-gSDE": (
        sb3.PPO,
        {
            "n_steps": 64,
            "batch_size": 64,
            "n_epochs": 1,
            "use_sde": True,
            "policy_kwargs": {"activation_fn": th.nn.ReLU, "net_arch": {"pi": [24], "vf": [8]}},
        },
    ),
}


RECURRENT = (
    sb3_contrib.RecurrentPPO,
    {"n_steps": 64, "batch_size": 64, "n_epochs": 1, "policy_kwargs": {"lstm_hidden_size": 16}},
)
DEFAULT_POLICY = {sb3_contrib.ARS: "LinearPolicy", sb3_contrib.RecurrentPPO: "MlpLstmPolicy"}


def train_model(name: str, cls: type, options: dict, out: Path) -> Path:
    options = dict(options)
    policy = options.pop("policy", DEFAULT_POLICY.get(cls, "MlpPolicy"))
    kwargs = options.pop("policy_kwargs", {})
    if "net_arch" not in kwargs and policy != "LinearPolicy":
        kwargs["net_arch"] = [16] if cls is sb3_contrib.ARS else [16, 16]
    model = cls(policy, gym.make(ENV_ID), policy_kwargs=kwargs, seed=0, **options)
    model.learn(200)
    path = out / f"{name}.zip"
    model.save(path)
    return path


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """Each algorithm's model, trained on first use: ``models(name)`` is its zip."""
    out = tmp_path_factory.mktemp("algorithms")
    made: dict[str, Path] = {}

    def get(name: str) -> Path:
        if name not in made:
            cls, options = RECURRENT if name == "RecurrentPPO" else ALGORITHMS[name]
            made[name] = train_model(name, cls, options, out)
        return made[name]

    return get


def observations(n: int = 8) -> np.ndarray:
    env = gym.make(ENV_ID)
    obs = np.stack([env.reset(seed=i)[0] for i in range(n)])
    env.close()
    return obs


def load_quietly(spec, **kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnknownPhysicsWarning)
        return load_policy(spec, **kwargs)


@pytest.mark.parametrize("name", list(ALGORITHMS))
def test_a_model_of_every_algorithm_acts_as_in_its_own_library(models, name):
    path = models(name)
    cls = ALGORITHMS[name][0]
    loaded = load_quietly(path)
    obs = observations()
    expected, _ = cls.load(path, device="cpu").predict(obs, deterministic=True)
    np.testing.assert_array_equal(loaded(obs), np.clip(expected, -1, 1).astype(np.float32))
    np.testing.assert_allclose(loaded(obs[0]), loaded(obs)[0], atol=1e-6)  # one, or a batch
    assert not loaded.recurrent


@pytest.mark.parametrize("name", ["TD3", "TQC", "CrossQ"])
def test_foosball_eval_rates_a_model_of_another_algorithm(models, name, tmp_path):
    path, out = models(name), tmp_path / "eval.json"
    argv = ["eval", str(path), "--env", ENV_ID, "--episodes", "2", "--json", str(out)]
    with pytest.warns(UnknownPhysicsWarning):
        assert main(argv) == 0
    result = json.loads(out.read_text())
    assert (result["episodes"], result["env_id"], result["policy"]) == (2, ENV_ID, str(path))
    expected = evaluate(load_quietly(path), ENV_ID, episodes=2)
    assert result["mean_reward"] == pytest.approx(expected.mean_reward)


def test_a_recurrent_policy_remembers_through_an_episode_and_forgets_at_the_next(models):
    path = models("RecurrentPPO")
    loaded = load_quietly(path)
    model = sb3_contrib.RecurrentPPO.load(path, device="cpu")
    assert loaded.recurrent
    env = gym.make(ENV_ID)
    remembered = False
    for episode in range(2):
        obs, _ = env.reset(seed=episode)
        loaded.reset()
        state, start = None, np.ones(1, bool)
        for step in range(30):
            expected, state = model.predict(
                obs, state=state, episode_start=start, deterministic=True
            )
            action = loaded(obs)
            np.testing.assert_array_equal(action, np.clip(expected, -1, 1))
            if step == 5:
                fresh = load_quietly(path)(obs)  # the same observation, with no memory
                remembered = remembered or not np.array_equal(fresh, action)
            start = np.zeros(1, bool)
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    env.close()
    assert remembered, "the memory changed no action: this test would not see it dropped"


def test_foosball_eval_starts_a_recurrent_policy_afresh_each_episode(models, tmp_path, monkeypatch):
    path = models("RecurrentPPO")
    model = sb3_contrib.RecurrentPPO.load(path, device="cpu")
    env = gym.make(ENV_ID)
    expected, rewards = [], []
    for seed in range(3):  # as RecurrentPPO plays: a zero state at each episode's start
        obs, _ = env.reset(seed=seed)
        state, start, total, done = None, np.ones(1, bool), 0.0, False
        while not done:
            action, state = model.predict(obs, state=state, episode_start=start, deterministic=True)
            expected.append(np.clip(action, -1, 1))
            obs, reward, terminated, truncated, _ = env.step(expected[-1])
            total, start, done = total + reward, np.zeros(1, bool), terminated or truncated
        rewards.append(total)
    env.close()
    played = []

    def recording(self, obs):
        played.append(call(self, obs))
        return played[-1]

    call = LoadedPolicy.__call__
    monkeypatch.setattr(LoadedPolicy, "__call__", recording)
    out = tmp_path / "eval.json"
    argv = ["eval", str(path), "--env", ENV_ID, "--episodes", "3", "--json", str(out)]
    with pytest.warns(UnknownPhysicsWarning):
        assert main(argv) == 0
    np.testing.assert_array_equal(np.array(played), np.array(expected))
    assert json.loads(out.read_text())["mean_reward"] == pytest.approx(np.mean(rewards))


def test_foosball_play_refuses_a_recurrent_policy_in_one_line(models, capsys):
    pytest.importorskip("canopen")
    path = models("RecurrentPPO")
    with pytest.raises(SystemExit) as exit_info, pytest.warns(UnknownPhysicsWarning):
        main(["play", str(path), "--env", ENV_ID, "--table", "sim", "--episodes", "1"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "recurrent" in err and "foosball eval" in err


def refused(spec: Path, capsys) -> str:
    """``foosball eval``'s error for ``spec``, checked to be one line and exit 2."""
    with pytest.raises(SystemExit) as exit_info, warnings.catch_warnings():
        warnings.simplefilter("ignore", UnknownPhysicsWarning)
        main(["eval", str(spec), "--env", ENV_ID, "--episodes", "1"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


def test_a_model_for_discrete_actions_is_refused_naming_what_loads(tmp_path, capsys):
    path = tmp_path / "dqn.zip"
    sb3.DQN("MlpPolicy", "CartPole-v1", seed=0).save(path)
    with pytest.raises(ModelLoadError, match="discrete"):
        load_quietly(path)
    err = refused(path, capsys)
    assert "DQN" in err and "PPO, A2C, SAC, TD3" in err and "RecurrentPPO" in err


class CustomExtractor(BaseFeaturesExtractor):
    """A feature extractor of the user's: code that only its own module holds."""

    def __init__(self, observation_space):
        super().__init__(observation_space, features_dim=4)
        self.net = th.nn.Linear(int(np.prod(observation_space.shape)), 4)

    def forward(self, obs):
        return self.net(obs)


def test_a_model_whose_settings_name_code_of_its_own_is_refused(tmp_path, capsys):
    path = tmp_path / "custom.zip"
    kwargs = {"features_extractor_class": CustomExtractor, "net_arch": [8]}
    sb3.PPO("MlpPolicy", gym.make(ENV_ID), policy_kwargs=kwargs, n_steps=64).save(path)
    err = refused(path, capsys)
    assert "features_extractor_class" in err and "CustomExtractor" in err
