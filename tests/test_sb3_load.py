"""This package's model zips load with Stable-Baselines3's own ``PPO.load`` and ``SAC.load``
(given :func:`sb3_objects` for the fields the zips keep as plain text, not pickles), and the
model SB3 loads acts as :func:`load_policy`'s on the same observations."""

from __future__ import annotations

import pytest

pytest.importorskip("stable_baselines3")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
from stable_baselines3 import PPO, SAC  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # noqa: E402

from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading import (  # noqa: E402
    builtin_path,
    load_policy,
    sb3_normalize,
    sb3_objects,
)
from foosball_gym.training.sb3.trainer import train  # noqa: E402

ALGOS = {"ppo": PPO, "sac": SAC}
SMALL = {"n_envs": 1, "batch_size": 64, "eval_freq": 10_000, "eval_episodes": 1}


@pytest.fixture(scope="module", params=["ppo", "sac"])
def run(request, tmp_path_factory):
    """A short run of each algorithm; SAC's learning rate decays, a schedule its zip keeps
    only as a pickle."""
    algo = request.param
    settings = {"n_steps": 64, "n_epochs": 1} if algo == "ppo" else {"lr_schedule": "linear"}
    out = tmp_path_factory.mktemp(algo) / "run"
    train(TrainConfig("Foosball-Block-v0", algo=algo, timesteps=256, **SMALL, **settings), out)
    return algo, out


def raw_observations(n: int = 40) -> np.ndarray:
    env = gym.make("Foosball-Block-v0")
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=0)
    seen = []
    for _ in range(n):
        seen.append(obs)
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            obs, _ = env.reset(seed=int(rng.integers(1000)))
    env.close()
    return np.array(seen)


def test_sb3_s_own_load_gives_the_actions_of_load_policy(run):
    algo, out = run
    path = out / "model.zip"
    model = ALGOS[algo].load(path, custom_objects=sb3_objects(path), device="cpu")
    venv = sb3_normalize(path, DummyVecEnv([lambda: gym.make("Foosball-Block-v0")]))
    assert isinstance(venv, VecNormalize)  # the run normalised its observations
    obs = raw_observations()
    sb3_actions, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    np.testing.assert_allclose(sb3_actions, load_policy(out)(obs), atol=1e-6)
    assert model.observation_space == venv.observation_space
    assert model.num_timesteps == 256
    venv.close()


def test_a_model_loaded_by_sb3_trains_on(run, tmp_path):
    algo, out = run
    path = out / "model.zip"
    model = ALGOS[algo].load(path, custom_objects=sb3_objects(path), device="cpu")
    venv = sb3_normalize(path, DummyVecEnv([lambda: gym.make("Foosball-Block-v0")]))
    venv.training = True  # fine-tuning updates the statistics, as training did
    model.set_env(venv)
    model.learn(128, reset_num_timesteps=False)
    assert model.num_timesteps >= 256 + 128
    model.save(tmp_path / "more.zip")  # SB3's own zip, with its pickles
    assert ALGOS[algo].load(tmp_path / "more.zip", device="cpu").num_timesteps >= 384


def test_a_shipped_policy_loads_into_sb3_and_acts_as_its_snapshot():
    path = builtin_path("block") / "model.zip"
    model = PPO.load(path, custom_objects=sb3_objects(path), device="cpu")
    venv = sb3_normalize(path, DummyVecEnv([lambda: gym.make("Foosball-Block-v0")]))
    obs = raw_observations()
    sb3_actions, _ = model.predict(venv.normalize_obs(obs), deterministic=True)
    # builtin:block is a residual: its snapshot is the network, without the scripted baseline.
    np.testing.assert_allclose(sb3_actions, load_policy("builtin:block").policy(obs), atol=1e-6)


def test_without_the_objects_sb3_s_load_fails_on_the_spaces_it_cannot_unpickle():
    # Why sb3_objects is needed: the zips hold no pickle for SB3 to rebuild the spaces from.
    with pytest.raises(ValueError, match="not a Gymnasium space"):
        PPO.load(builtin_path("block") / "model.zip", device="cpu")


class Plant:
    """Unpickled, it writes ``marker``: what a crafted model file could do."""

    def __init__(self, marker) -> None:
        self.marker = marker

    def __reduce__(self):
        return exec, (f"open({str(self.marker)!r}, 'w').write('ran')",)


def test_loading_with_sb3_objects_unpickles_nothing_a_zip_holds(tmp_path):
    import base64
    import json
    import pickle
    import zipfile

    marker, path = tmp_path / "ran", tmp_path / "model.zip"
    with zipfile.ZipFile(builtin_path("block") / "model.zip") as archive:
        entries = {n: archive.read(n) for n in archive.namelist()}
    data = json.loads(entries["data"])
    planted = base64.b64encode(pickle.dumps(Plant(marker))).decode()
    for key in ("observation_space", "policy_class", "lr_schedule", "_last_obs"):
        data[key][":serialized:"] = planted
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as archive:
        for name, content in entries.items():
            archive.writestr(name, content)
    PPO.load(path, custom_objects=sb3_objects(path), device="cpu")
    assert not marker.exists()
    with pytest.raises(Exception):  # noqa: B017 - what fails after the plant ran is SB3's
        PPO.load(path, device="cpu")
    assert marker.exists()  # the plant is live: SB3's load without the objects runs it
