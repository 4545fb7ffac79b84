"""learner: jax takes SB3's PPO update's steps (to rounding), and a run trained with it is an
ordinary SB3 PPO run: it checkpoints, resumes with Adam's state, and loads with PPO.load."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("jax")

import torch as th  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading.sb3_load import sb3_objects  # noqa: E402
from foosball_gym.training.sb3.jax_ppo import JaxPPO  # noqa: E402

SETTINGS = {
    "n_steps": 64,
    "batch_size": 64,
    "n_epochs": 4,
    "learning_rate": 3e-4,
    "seed": 3,
    "device": "cpu",
    "policy_kwargs": {
        "net_arch": [64, 64],
        "log_std_init": -1.0,
        "optimizer_kwargs": {"fused": True, "eps": 1e-8},
    },
}


def adam_state(model) -> dict[int, dict[str, th.Tensor]]:
    return model.policy.optimizer.state_dict()["state"]


@pytest.mark.parametrize(
    ("target_kl", "clip_range_vf", "use_sde"),
    # The recipes'; SB3's early stop and clipped value loss; gSDE's state-dependent spread.
    [(None, None, False), (0.002, 0.5, False), (None, None, True)],
)
def test_the_jax_update_takes_sb3_s_steps(target_kl, clip_range_vf, use_sde):
    venv = make_vec_env("Foosball-Block-v0", n_envs=2, seed=1)
    settings = {**SETTINGS, "target_kl": target_kl, "clip_range_vf": clip_range_vf}
    if use_sde:
        settings.update(use_sde=True, sde_sample_freq=4)
    sb3, jax_ppo = PPO("MlpPolicy", venv, **settings), JaxPPO("MlpPolicy", venv, **settings)
    stopped_early = False
    for rollout in range(2):
        # One rollout and SB3's update of it, then each update again from where it began.
        sb3.learn(128, reset_num_timesteps=rollout == 0)
        before = copy.deepcopy(sb3.policy.state_dict())
        adam = copy.deepcopy(sb3.policy.optimizer.state_dict())
        steps_before = adam["state"][0]["step"].item()
        jax_ppo.policy.load_state_dict(before)
        jax_ppo.policy.optimizer.load_state_dict(adam)
        jax_ppo.rollout_buffer = sb3.rollout_buffer
        jax_ppo._current_progress_remaining = sb3._current_progress_remaining
        jax_ppo._n_updates = sb3._n_updates
        jax_ppo.set_logger(sb3.logger)
        shuffles = np.random.get_state()
        sb3.train()
        sb3_log = dict(sb3.logger.name_to_value)
        np.random.set_state(shuffles)
        jax_ppo.train()
        jax_log = dict(jax_ppo.logger.name_to_value)

        after, got = sb3.policy.state_dict(), jax_ppo.policy.state_dict()
        moved = max((after[k] - before[k]).abs().max().item() for k in before)
        assert moved > 1e-3  # the update did something worth comparing
        for name in before:
            th.testing.assert_close(got[name], after[name], atol=moved * 1e-3, rtol=0)
        theirs, ours = adam_state(sb3), adam_state(jax_ppo)
        assert theirs.keys() == ours.keys()
        for i in theirs:
            assert ours[i]["step"].item() == theirs[i]["step"].item()
            for key in ("exp_avg", "exp_avg_sq"):
                th.testing.assert_close(ours[i][key], theirs[i][key], rtol=1e-3, atol=1e-9)
        assert jax_ppo._n_updates == sb3._n_updates
        # 4 epochs of 2 minibatches, unless the KL limit stopped it.
        stopped_early |= theirs[0]["step"].item() - steps_before < 8
        for key in (
            "train/policy_gradient_loss",
            "train/value_loss",
            "train/approx_kl",
            "train/entropy_loss",
        ):
            assert jax_log[key] == pytest.approx(sb3_log[key], rel=1e-3, abs=1e-7), key
    # The limit is small enough that SB3 stopped early: the comparison covered it.
    assert stopped_early == (target_kl is not None)


def test_importing_jax_leaves_numpy_s_generator_alone():
    # Importing JAX draws from NumPy's global generator, which SB3 shuffles minibatches with: in
    # a fresh interpreter, as at a run's start.
    code = (
        "import numpy as np; np.random.seed(5);"
        "from foosball_gym.training.sb3.jax_ppo import import_jax; import_jax();"
        "print(list(np.random.permutation(10)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    np.random.seed(5)
    assert out.stdout.strip() == str(list(np.random.permutation(10)))


def load(path):
    return PPO.load(path, device="cpu", custom_objects=sb3_objects(path))


SMALL = ["--n-envs", "2", "--n-steps", "64", "--batch-size", "64"]
SMALL += ["--checkpoint-freq", "128", "--eval-freq", "100000", "--eval-episodes", "1"]
SMALL += ["--lr-schedule", "constant", "--no-progress", "--learner", "jax"]


def test_a_jax_run_resumes_with_adam_and_loads_in_plain_sb3(tmp_path, capsys):
    run = tmp_path / "run"
    argv = ["train", "Foosball-Block-v0", "--timesteps", "256", "--out", str(run), *SMALL]
    assert main(argv) == 0
    assert json.loads((run / "config.json").read_text())["learner"] == "jax"

    def adam_steps(path):
        return {s["step"].item() for s in adam_state(load(path)).values()}

    assert adam_steps(run / "model.zip") == {80.0}  # 2 updates x 20 epochs x 2 minibatches
    # The last checkpoint was written as its rollout ended, before that rollout's update.
    assert adam_steps(run / "checkpoints" / "model_0000000256.zip") == {40.0}
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--timesteps", "512", "--no-progress"]) == 0
    resumed = load(run / "model.zip")
    # Adam went on from the checkpoint's 40 steps through two more updates (an optimiser
    # started afresh would stand at 80).
    assert adam_steps(run / "model.zip") == {120.0}
    assert resumed.num_timesteps == 512


def test_two_jax_runs_with_one_seed_are_the_same(tmp_path):
    params = []
    for name in ("a", "b"):
        run = tmp_path / name
        argv = ["train", "Foosball-Block-v0", "--timesteps", "256", "--out", str(run), *SMALL]
        assert main([*argv, "--seed", "4"]) == 0
        params.append(load(run / "model.zip").policy.state_dict())
    for name, value in params[0].items():
        th.testing.assert_close(params[1][name], value, rtol=0, atol=0)


def test_a_rollout_that_minibatches_do_not_divide_is_updated_by_sb3_with_a_warning():
    settings = {**SETTINGS, "batch_size": 48}  # 64 samples a rollout

    def model(cls):
        return cls("MlpPolicy", make_vec_env("Foosball-Block-v0", n_envs=1, seed=1), **settings)

    sb3 = model(PPO)
    sb3.learn(64)
    jax_ppo = model(JaxPPO)  # seeded alike: the same weights, rollout and minibatches
    with pytest.warns(UserWarning, match="batch_size 48 does not divide the rollout's 64"):
        jax_ppo.learn(64)
    # SB3's own update, to the bit (both collected the same rollout from the same seed).
    for name, value in sb3.policy.state_dict().items():
        th.testing.assert_close(jax_ppo.policy.state_dict()[name], value, rtol=0, atol=0)


def test_ppo_updates_in_jax_unless_told_and_sac_in_torch():
    for algo, learner in (("ppo", "jax"), ("sac", "torch"), ("crossq", "torch")):
        config = TrainConfig("Foosball-Block-v0", algo=algo)
        config.check()
        assert config.learner == learner
    config = TrainConfig("Foosball-Block-v0", learner="torch")
    config.check()
    assert config.learner == "torch"


def test_the_jax_learner_is_refused_where_it_cannot_run(monkeypatch):
    with pytest.raises(ValueError, match="unknown learner 'tf'; allowed: torch, jax"):
        TrainConfig("Foosball-Block-v0", learner="tf").check()
    with pytest.raises(ValueError, match="learner jax runs PPO's update; sac takes learner torch"):
        TrainConfig("Foosball-Block-v0", algo="sac", learner="jax").check()
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "jax" else real(name, *a)
    )
    with pytest.raises(ValueError, match=r"learner jax needs JAX, which is not installed"):
        TrainConfig("Foosball-Block-v0", learner="jax").check()


def test_the_jax_learner_refuses_a_gsde_it_does_not_compute():
    venv = make_vec_env("Foosball-Block-v0", n_envs=1, seed=1)
    with pytest.raises(ValueError, match="gSDE with SB3's defaults"):
        JaxPPO("MlpPolicy", venv, use_sde=True, policy_kwargs={"use_expln": True}, device="cpu")
