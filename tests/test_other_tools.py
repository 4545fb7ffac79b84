"""The environments from other tools: Gymnasium's "module:id" form in a process that never
imported the package, RLlib's env runners, RL Zoo with the shipped hyperparameter files, and
Gymnasium's RecordVideo (docs/other-tools.md)."""

from __future__ import annotations

import os
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
    reason='needs the train extra: pip install -e ".[train]"',
)
needs_zoo = pytest.mark.skipif(
    find_spec("rl_zoo3") is None, reason='needs the zoo extra: pip install -e ".[zoo]"'
)
needs_rllib = pytest.mark.skipif(
    any(find_spec(m) is None for m in ("ray", "torch")),
    reason='needs the distributed extra: pip install -e ".[distributed]"',
)

BLOCK = "Foosball-Block-v0"
# Ray runs this in each of its worker processes before they take work.
SETUP_HOOK = "foosball_gym.registration.register_envs"


def fresh_python(code: str, cwd: Path) -> subprocess.CompletedProcess:
    """``code`` run by a new interpreter, which has imported nothing of the package."""
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True, timeout=300
    )


# ------------------------------------------------------------------ Gymnasium's module:id


def test_a_module_prefixed_id_makes_the_env_where_nothing_imported_the_package(tmp_path):
    # gym.make_vec of the id is what RLlib's env runners call; async makes each env in a
    # process of its own.
    code = (
        "import numpy as np, gymnasium as gym\n"
        "env = gym.make('foosball_gym:Foosball-Block-v0')\n"
        "obs, _ = env.reset(seed=0)\n"
        "assert obs.shape == (6,) and env.spec.max_episode_steps == 90\n"
        "env.close()\n"
        "for mode in ('sync', 'async'):\n"
        "    envs = gym.make_vec('foosball_gym:Foosball-Score-v0', num_envs=2,\n"
        "                        vectorization_mode=mode, ball_start='incoming')\n"
        "    envs.reset(seed=0)\n"
        "    envs.step(np.zeros((2, 2), np.float32))\n"
        "    envs.close()\n"
        "print('plain id afterwards:', 'Foosball-Block-v0' in gym.registry)\n"
    )
    before = fresh_python("import gymnasium as gym; gym.make('Foosball-Block-v0')", tmp_path)
    assert before.returncode != 0 and "Foosball-Block" in before.stderr
    after = fresh_python(code, tmp_path)
    assert after.returncode == 0, after.stderr[-3000:]
    assert "plain id afterwards: True" in after.stdout


# ------------------------------------------------------------------ RLlib's env runners


def rllib_run(env: str, runtime_env: dict | None) -> tuple[list, int]:
    """One PPO iteration on ``env`` with one env runner in its own process; the id of the
    environment the runner made and its process id, and this process's id."""
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig

    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False, runtime_env=runtime_env)
    algo = None
    try:
        config = (
            PPOConfig()
            .environment(env)
            .env_runners(num_env_runners=1, num_envs_per_env_runner=1, rollout_fragment_length=64)
            .training(train_batch_size_per_learner=64, minibatch_size=64, num_epochs=1)
            .rl_module(model_config={"fcnet_hiddens": [16]})
        )
        algo = config.build_algo()
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled_lifetime"] >= 64
        made = algo.env_runner_group.foreach_env_runner(
            lambda runner: (runner.env.unwrapped.envs[0].spec.id, os.getpid()),
            local_env_runner=False,
        )
        return made, os.getpid()
    finally:
        if algo is not None:
            algo.stop()
        ray.shutdown()


@needs_rllib
def test_rllib_env_runners_make_the_module_prefixed_id_with_no_setup():
    made, driver = rllib_run(f"foosball_gym:{BLOCK}", runtime_env=None)
    assert len(made) == 1
    env_id, runner = made[0]
    assert env_id == BLOCK and runner != driver


@needs_rllib
@pytest.mark.slow
def test_rllib_env_runners_make_the_plain_id_where_ray_runs_the_registration_hook():
    # docs/other-tools.md runs the same in the default suite (its example); here what the
    # runner made is checked too.
    made, driver = rllib_run(BLOCK, runtime_env={"worker_process_setup_hook": SETUP_HOOK})
    env_id, runner = made[0]
    assert env_id == BLOCK and runner != driver


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
    assert entry.pop("ent_coef", 0.0) == config.ent_coef
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
        pytest.skip('needs the zoo extra: pip install -e ".[zoo]"')
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
    # rl_zoo3.record_video on its own fails with a KeyError: nothing registered the id.
    command = [sys.executable, "-m", "foosball_gym.rl_zoo", "record_video", "--algo", "ppo"]
    command += ["--env", BLOCK, "-f", str(logs), "-n", "60", "-o", str(videos)]
    command += ["--env-kwargs", "render_width:64", "render_height:36"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
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
