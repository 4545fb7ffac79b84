"""gSDE (use_sde): a run explores with state-dependent noise, in either learner, records it,
and its model loads where any run's does; what cannot take it is refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading import load_policy  # noqa: E402
from foosball_gym.training.loading.sb3_load import sb3_objects  # noqa: E402
from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot  # noqa: E402

SMALL = ["--n-envs", "2", "--n-steps", "64", "--batch-size", "64", "--timesteps", "128"]
SMALL += ["--eval-freq", "100000", "--eval-episodes", "1", "--no-progress"]


@pytest.mark.parametrize("learner", ["jax", "torch"])
def test_a_gsde_run_records_it_and_its_model_loads(tmp_path, learner):
    if learner == "jax":
        pytest.importorskip("jax")
    run = tmp_path / "run"
    argv = ["train", "Foosball-Block-v0", "--out", str(run), "--learner", learner, *SMALL]
    assert main([*argv, "--use-sde", "--sde-sample-freq", "4", "--log-std-init", "-2"]) == 0
    config = json.loads((run / "config.json").read_text())
    assert (config["use_sde"], config["sde_sample_freq"]) == (True, 4)
    model = PPO.load(run / "model.zip", device="cpu", custom_objects=sb3_objects(run / "model.zip"))
    assert model.use_sde and model.sde_sample_freq == 4
    # gSDE's noise matrix: one row per unit of the last hidden layer (64), one column per action.
    assert tuple(model.policy.log_std.shape) == (64, 1)
    obs = np.array([[0.01, 0.0, 0.2, 0.1, -3.0, 0.5]])
    loaded = load_policy(run)
    normalised = loaded.policy.normalise(obs)
    expected, _ = model.predict(normalised, deterministic=True)
    # The package's loader, and a snapshot as self-play and the league keep them, play the
    # policy's mean, as SB3's deterministic predict does.
    np.testing.assert_allclose(loaded(obs[0]), expected[0], atol=1e-6)
    snapshot = tmp_path / "snapshot.pt"
    PolicySnapshot.of_model(model).save(snapshot)  # loaded without its env: no statistics
    np.testing.assert_allclose(PolicySnapshot.load(snapshot)(normalised[0]), expected[0], atol=1e-6)


def test_gsde_noise_depends_on_the_state():
    config = TrainConfig(
        "Foosball-Block-v0", n_envs=1, batch_size=128, use_sde=True, log_std_init=-2.0
    )
    config.check()
    from foosball_gym.training.sb3.model import build_model
    from foosball_gym.training.sb3.vec_env import make_env

    venv = make_env(config)
    try:
        policy = build_model(config, venv, None).policy
    finally:
        venv.close()
    import torch as th

    policy.reset_noise(1)
    spreads = []
    for obs in ([0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.1, 2.0, 0.4, -0.3, -7.0, 3.0]):
        distribution = policy.get_distribution(th.tensor([obs])).distribution
        spreads.append(distribution.stddev.item())
    # A plain Gaussian's spread is one number whatever the state; gSDE's is not.
    assert abs(spreads[0] - spreads[1]) > 1e-3


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"algo": "crossq", "use_sde": True}, "use_sde needs PPO or SAC, not crossq"),
        ({"use_sde": True, "sde_sample_freq": 0}, r"-1 \(new noise once a rollout\)"),
        ({"sde_sample_freq": 4}, "it needs use_sde"),
    ],
)
def test_gsde_settings_that_cannot_work_are_refused(bad, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig("Foosball-Block-v0", **bad).check()


def test_gsde_reaches_sac_and_a_settings_file_s_choice_can_be_undone(tmp_path, capsys):
    from foosball_gym.training.sb3.model import build_model
    from foosball_gym.training.sb3.vec_env import make_env

    config = TrainConfig("Foosball-Block-v0", algo="sac", n_envs=1, use_sde=True)
    config.check()
    venv = make_env(config)
    try:
        assert build_model(config, venv, None).use_sde
    finally:
        venv.close()
    settings = tmp_path / "sde.yaml"
    settings.write_text("use_sde: true\nsde_sample_freq: 4\n")
    run = tmp_path / "run"
    argv = ["train", "Foosball-Block-v0", "--config", str(settings), "--out", str(run), *SMALL]
    # The file's use_sde switched off, its sample frequency with it.
    assert main([*argv, "--no-use-sde", "--sde-sample-freq", "-1"]) == 0
    assert json.loads((run / "config.json").read_text())["use_sde"] is False
    with pytest.raises(SystemExit):
        main([*argv[: -len(SMALL)], "--no-use-sde", *SMALL, "--out", str(tmp_path / "r2")])
    assert "sde_sample_freq 4 says how often gSDE draws its noise" in capsys.readouterr().err
