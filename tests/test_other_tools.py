"""The environments from other tools: RL Zoo with the shipped hyperparameter files, and
Gymnasium's RecordVideo."""

from __future__ import annotations

import subprocess
import sys
from importlib.util import find_spec
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from foosball_gym import ENV_IDS
from foosball_gym.rl_zoo import ALGOS, hyperparams_file
from foosball_gym.rl_zoo.__main__ import main as rl_zoo_main

needs_train = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("stable_baselines3", "torch", "cv2")),
    reason='needs the train extra: pip install "foosball_gym[train]"',
)
needs_zoo = pytest.mark.skipif(
    find_spec("rl_zoo3") is None, reason='needs the zoo extra: pip install "foosball_gym[zoo]"'
)
BLOCK = "Foosball-Block-v0"


def fresh_python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    """``code`` run by a new interpreter, which has imported nothing of the package."""
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300
    )


# ------------------------------------------------------------------ RL Zoo


def zoo_hyperparams() -> dict:
    import yaml

    return yaml.safe_load(hyperparams_file("ppo").read_text())


@needs_train
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_the_rl_zoo_file_carries_the_settings_file_of_each_task(env_id):
    """Each entry is the task's `foosball train --config builtin:ENV_ID` in RL Zoo's terms, so a
    changed settings file fails here until the RL Zoo file follows it."""
    from foosball_gym.training.config_file import load_train_config

    config = load_train_config(f"builtin:{env_id}")
    entry = zoo_hyperparams()[env_id]
    lr = config.learning_rate
    assert entry.pop("learning_rate") == (lr if config.lr_schedule == "constant" else f"lin_{lr}")
    assert entry.pop("n_timesteps") == config.timesteps
    assert entry.pop("policy") == "MlpPolicy"
    # RL Zoo evaluates these two strings as Python.
    assert eval(entry.pop("normalize"), {}) == {
        "norm_obs": config.normalize,
        "norm_reward": config.normalize_reward,
    }
    assert eval(entry.pop("policy_kwargs"), {"dict": dict}) == {
        "net_arch": list(config.net_arch),
        "log_std_init": config.log_std_init,
    }
    assert entry.pop("env_kwargs", {}) == config.env_kwargs
    assert entry.pop("target_kl", None) == config.target_kl
    names = ("n_envs", "n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda", "clip_range")
    assert entry == {name: getattr(config, name) for name in names}
    assert config.algo == "ppo"


@needs_train
def test_the_rl_zoo_file_has_an_entry_for_every_id_and_nothing_else():
    assert list(zoo_hyperparams()) == list(ENV_IDS)
    assert hyperparams_file().name == "ppo.yml" and ALGOS == ("ppo",)


def test_asking_for_an_algorithm_without_a_file_names_those_there_are():
    with pytest.raises(ValueError, match="'sac'; shipped: ppo"):
        hyperparams_file("sac")


def rl_zoo_train(env_id: str, logs: Path, steps: int) -> subprocess.CompletedProcess:
    """``python -m rl_zoo3.train`` of ``env_id`` as docs/other-tools.md gives it."""
    command = [sys.executable, "-m", "rl_zoo3.train", "--algo", "ppo", "--env", env_id]
    command += ["--gym-packages", "foosball_gym", "-conf", str(hyperparams_file("ppo"))]
    command += ["-n", str(steps), "-f", str(logs), "--seed", "0", "--num-threads", "1"]
    return subprocess.run(command, cwd=logs.parent, capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def zoo_block_run(tmp_path_factory) -> Path:
    """RL Zoo's run of Block, 5000 steps with the shipped file: its log folder."""
    if find_spec("rl_zoo3") is None:
        pytest.skip('needs the zoo extra: pip install "foosball_gym[zoo]"')
    logs = tmp_path_factory.mktemp("zoo") / "logs"
    done = rl_zoo_train(BLOCK, logs, 5000)
    assert done.returncode == 0, done.stderr[-3000:]
    return logs / "ppo" / f"{BLOCK}_1"


@needs_zoo
def test_rl_zoo_trains_block_with_the_shipped_hyperparameters(zoo_block_run):
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    model = PPO.load(zoo_block_run / f"{BLOCK}.zip", device="cpu")
    assert model.num_timesteps >= 5000
    assert (model.n_envs, model.n_steps, model.batch_size, model.n_epochs) == (8, 128, 256, 8)
    assert model.policy_kwargs == {"net_arch": [256, 128, 64], "log_std_init": 0.0}
    assert model.lr_schedule(1.0) == pytest.approx(1e-3)
    venv = DummyVecEnv([lambda: gym.make(BLOCK)])
    norm = VecNormalize.load(str(zoo_block_run / BLOCK / "vecnormalize.pkl"), venv)
    assert (norm.norm_obs, norm.norm_reward, norm.gamma) == (True, False, 0.99)
    venv.close()


@needs_zoo
@needs_train
def test_rl_zoo_records_a_video_of_its_run_through_the_package_runner(zoo_block_run, tmp_path):
    import cv2

    logs = zoo_block_run.parent.parent
    videos = tmp_path / "videos"
    # On its own, rl_zoo3.record_video fails with a KeyError: nothing registered the id.
    alone = [sys.executable, "-m", "rl_zoo3.record_video", "--algo", "ppo", "--env", BLOCK]
    args = ["-f", str(logs), "-n", "60", "-o", str(videos)]
    args += ["--env-kwargs", "render_width:64", "render_height:36"]
    failed = subprocess.run([*alone, *args], capture_output=True, text=True, timeout=300)
    assert failed.returncode != 0 and "KeyError" in failed.stderr
    runner = [sys.executable, "-m", "foosball_gym.rl_zoo", "record_video"]
    done = subprocess.run(
        [*runner, "--algo", "ppo", "--env", BLOCK, *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    (video,) = videos.glob("*.mp4")
    capture = cv2.VideoCapture(str(video))
    frames = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
    size = (capture.get(cv2.CAP_PROP_FRAME_WIDTH), capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
    capture.release()
    assert frames >= 60 and size == (64, 36)


@needs_zoo
@pytest.mark.slow
@pytest.mark.parametrize("env_id", [e for e in ENV_IDS if e != BLOCK])
def test_rl_zoo_trains_every_other_task_with_the_shipped_hyperparameters(env_id, tmp_path):
    logs = tmp_path / "logs"
    done = rl_zoo_train(env_id, logs, 3000)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (logs / "ppo" / f"{env_id}_1" / f"{env_id}.zip").is_file()


def test_the_runner_names_its_scripts_for_one_it_does_not_run(capsys):
    assert rl_zoo_main(["record_training"]) == 2
    assert "unknown script 'record_training'; one of train, enjoy, record_video" in (
        capsys.readouterr().err
    )
    assert rl_zoo_main([]) == 2


# ------------------------------------------------------------------ Gymnasium's RecordVideo


@needs_train
def test_record_video_writes_an_mp4_of_one_episode(tmp_path):
    """gymnasium.wrappers.RecordVideo writes through moviepy, which the train extra brings."""
    import cv2

    env = gym.wrappers.RecordVideo(
        gym.make(BLOCK, render_mode="rgb_array", render_width=64, render_height=36),
        str(tmp_path / "videos"),
        episode_trigger=lambda episode: episode == 0,
        disable_logger=True,
    )
    env.reset(seed=0)
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.zeros(1, np.float32))
        steps, done = steps + 1, terminated or truncated
    env.close()
    (video,) = (tmp_path / "videos").glob("*.mp4")
    capture = cv2.VideoCapture(str(video))
    size = (capture.get(cv2.CAP_PROP_FRAME_WIDTH), capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
    frames = 0
    while capture.read()[0]:
        frames += 1
    capture.release()
    # RecordVideo keeps the frame of the reset and one a step; moviepy 2 writes all but the
    # last of them.
    assert steps <= frames <= steps + 1 and size == (64, 36)
