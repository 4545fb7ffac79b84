"""``foosball eval`` and ``load_policy`` read an RL Zoo run: its model, its environment's options
and, where trusted, its normalisation; what they cannot apply they refuse in one line."""

from __future__ import annotations

import json
import pickle
import shutil
import subprocess
import sys
import warnings
from importlib.util import find_spec
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

# Looked up, not imported: importing rl_zoo3 replaces Gymnasium's TimeLimit in the whole
# process with one that adds "TimeLimit.truncated" to the last step's info. The runs below
# start RL Zoo in processes of their own.
if find_spec("rl_zoo3") is None:
    pytest.skip('needs the zoo extra: pip install -e ".[zoo]"', allow_module_level=True)

import stable_baselines3 as sb3  # noqa: E402
import yaml  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.training.loading import (  # noqa: E402
    ModelLoadError,
    UnknownPhysicsWarning,
    load_policy,
)

ENV_ID = "Foosball-Block-v0"
# Without the joint velocities the observations are shorter: a model evaluated without the
# run's options fails to fit, rather than passing unnoticed.
ENV_KWARGS = {"joint_velocities": False}
HYPERPARAMS = {
    ENV_ID: {
        "policy": "MlpPolicy",
        "normalize": True,
        "n_envs": 2,
        "n_timesteps": 256,
        "n_steps": 64,
        "batch_size": 64,
        "n_epochs": 1,
    }
}


@pytest.fixture(scope="module")
def zoo_run(tmp_path_factory):
    """A run of ``python -m rl_zoo3.train``, with normalisation and a checkpoint."""
    root = tmp_path_factory.mktemp("zoo")
    (root / "hyperparams.yml").write_text(yaml.safe_dump(HYPERPARAMS))
    command = [
        sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", ENV_ID,
        "--gym-packages", "foosball_gym", "-conf", "hyperparams.yml", "-f", "logs",
        "--env-kwargs", "joint_velocities:False", "--eval-freq", "-1", "--save-freq", "128",
        "--seed", "0", "--verbose", "0",
    ]  # fmt: skip
    done = subprocess.run(command, cwd=root, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    run = root / "logs" / "ppo" / f"{ENV_ID}_1"
    # The layout RL Zoo writes, which the loader reads.
    for name in (f"{ENV_ID}.zip", "rl_model_128_steps.zip"):
        assert (run / name).is_file(), sorted(p.name for p in run.iterdir())
    for name in ("vecnormalize.pkl", "config.yml", "args.yml"):
        assert (run / ENV_ID / name).is_file(), sorted(p.name for p in (run / ENV_ID).iterdir())
    return run


@pytest.fixture
def run_copy(zoo_run, tmp_path):
    return Path(shutil.copytree(zoo_run, tmp_path / zoo_run.name))


def load(spec, trust=True):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UnknownPhysicsWarning)
        return load_policy(spec, trust=trust)


def eval_refused(argv: list[str], capsys) -> str:
    with pytest.raises(SystemExit) as exit_info, warnings.catch_warnings():
        warnings.simplefilter("ignore", UnknownPhysicsWarning)
        main(argv)
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    return err


def observations(n: int = 8) -> np.ndarray:
    env = gym.make(ENV_ID, **ENV_KWARGS)
    obs = np.stack([env.reset(seed=i)[0] for i in range(n)])
    env.close()
    return obs


def true_figure(run: Path, episodes: int) -> float:
    """The mean reward as RL Zoo's own objects play: the model through its VecNormalize."""
    model = sb3.PPO.load(run / f"{ENV_ID}.zip", device="cpu")
    venv = DummyVecEnv([lambda: gym.make(ENV_ID, **ENV_KWARGS)])
    norm = VecNormalize.load(str(run / ENV_ID / "vecnormalize.pkl"), venv)
    env, rewards = gym.make(ENV_ID, **ENV_KWARGS), []
    for seed in range(episodes):
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(norm.normalize_obs(obs), deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(np.clip(action, -1, 1))
            total, done = total + reward, terminated or truncated
        rewards.append(total)
    env.close()
    venv.close()
    return float(np.mean(rewards))


def test_a_trusted_run_is_evaluated_with_its_normalisation_and_options(zoo_run, tmp_path):
    out = tmp_path / "eval.json"
    argv = ["eval", str(zoo_run), "--trust-model", "--episodes", "3", "--json", str(out)]
    with pytest.warns(UnknownPhysicsWarning):
        assert main(argv) == 0
    result = json.loads(out.read_text())
    assert (result["env_id"], result["env_kwargs"]) == (ENV_ID, ENV_KWARGS)
    assert result["mean_reward"] == pytest.approx(true_figure(zoo_run, 3))


def test_the_loaded_policy_acts_as_the_model_behind_its_vecnormalize(zoo_run):
    loaded = load(zoo_run)
    assert (loaded.env_id, loaded.env_kwargs) == (ENV_ID, ENV_KWARGS)
    model = sb3.PPO.load(zoo_run / f"{ENV_ID}.zip", device="cpu")
    venv = DummyVecEnv([lambda: gym.make(ENV_ID, **ENV_KWARGS)])
    norm = VecNormalize.load(str(zoo_run / ENV_ID / "vecnormalize.pkl"), venv)
    obs = observations()
    expected, _ = model.predict(norm.normalize_obs(obs), deterministic=True)
    np.testing.assert_array_equal(loaded(obs), np.clip(expected, -1, 1))
    raw, _ = model.predict(obs, deterministic=True)
    assert not np.allclose(raw, expected), "the statistics change nothing: a test that cannot fail"
    # The final model's zip, named, is the run's.
    np.testing.assert_array_equal(load(zoo_run / f"{ENV_ID}.zip")(obs), loaded(obs))


def test_a_checkpoint_of_the_run_loads_with_the_run_s_options(zoo_run):
    loaded = load(zoo_run / "rl_model_128_steps.zip")
    assert (loaded.env_id, loaded.env_kwargs) == (ENV_ID, ENV_KWARGS)
    assert loaded.policy.obs_mean is not None


class Plant:
    """Unpickled, it writes ``marker``: what a crafted statistics file could do instead."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return exec, (f"open({str(self.marker)!r}, 'w').write('ran')",)


def test_an_untrusted_run_is_refused_in_one_line_naming_the_flag(run_copy, tmp_path, capsys):
    marker = tmp_path / "ran"
    (run_copy / ENV_ID / "vecnormalize.pkl").write_bytes(pickle.dumps(Plant(marker)))
    err = eval_refused(["eval", str(run_copy), "--episodes", "1"], capsys)
    assert "--trust-model" in err and "vecnormalize.pkl" in err and "pickle" in err
    with pytest.raises(ModelLoadError, match="trust"):
        load(run_copy, trust=False)
    assert not marker.exists()


def test_a_run_without_its_statistics_is_refused(run_copy, capsys):
    (run_copy / ENV_ID / "vecnormalize.pkl").unlink()
    err = eval_refused(["eval", str(run_copy), "--trust-model", "--episodes", "1"], capsys)
    assert "normalize" in err and "vecnormalize.pkl" in err and "missing" in err


def test_a_run_trained_through_a_wrapper_is_refused(run_copy, capsys):
    config = run_copy / ENV_ID / "config.yml"
    wrapper = "sb3_contrib.common.wrappers.TimeFeatureWrapper"
    config.write_text(config.read_text() + f"  - - env_wrapper\n    - {wrapper}\n")
    err = eval_refused(["eval", str(run_copy), "--trust-model", "--episodes", "1"], capsys)
    assert "env_wrapper" in err and "TimeFeatureWrapper" in err and "rl_zoo3.enjoy" in err


def test_a_run_s_physics_revision_is_unknown(zoo_run):
    with pytest.warns(UnknownPhysicsWarning, match="unknown") as caught:
        load_policy(zoo_run, trust=True)
    assert len(caught) == 1
    assert "revision 1" not in str(caught[0].message)
