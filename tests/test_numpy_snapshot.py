"""A run's evaluations play its PPO policy copied into NumPy: the actions SB3's deterministic
predict gives (to float32 rounding), on observations normalised as the run normalises them, and
the same episodes; a policy it cannot copy is played by the PyTorch snapshot."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import torch as th  # noqa: E402

from foosball_gym.evaluation import evaluate  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot  # noqa: E402
from foosball_gym.training.sb3.model import build_model  # noqa: E402
from foosball_gym.training.sb3.numpy_snapshot import NumpySnapshot  # noqa: E402
from foosball_gym.training.sb3.vec_env import make_env  # noqa: E402


@pytest.fixture
def model_of():
    made = []

    def build(**kwargs):
        config = TrainConfig(
            "Foosball-Block-v0", n_envs=1, batch_size=64, vec_env="dummy", **kwargs
        )
        config.check()
        venv = make_env(config)
        made.append(venv)
        return build_model(config, venv, None)

    yield build
    for venv in made:
        venv.close()


def _stir(model, rng):
    """Weights and statistics far from their start, so that the actions spread over the
    action space (some clipped) and the normalisation matters."""
    with th.no_grad():
        for p in model.policy.parameters():
            p.add_(th.as_tensor(rng.normal(scale=0.6, size=tuple(p.shape)), dtype=p.dtype))
    stats = model.get_env().obs_rms
    stats.mean = rng.normal(scale=0.3, size=stats.mean.shape)
    stats.var = rng.uniform(0.05, 2.0, size=stats.var.shape)


def test_the_numpy_snapshot_plays_what_predict_plays(model_of):
    model = model_of(normalize=True)
    rng = np.random.default_rng(4)
    _stir(model, rng)
    fast, slow = NumpySnapshot.of_model(model), PolicySnapshot.of_model(model)
    assert isinstance(fast, NumpySnapshot)
    assert fast.observation_size == slow.observation_size
    obs = rng.normal(scale=0.5, size=(64, fast.observation_size))
    actions = fast(obs)
    np.testing.assert_allclose(actions, slow(obs), atol=1e-5)
    assert actions.dtype == np.float32 and np.abs(actions).max() == 1.0
    assert 0.0 < np.mean(np.abs(actions) == 1.0) < 1.0, "some actions should be clipped"
    np.testing.assert_allclose(fast(obs[3]), slow(obs[3]), atol=1e-5)
    # Without the run's statistics the actions are others: they are applied.
    plain = NumpySnapshot(fast.net)
    assert np.abs(plain(obs) - actions).max() > 0.1
    # The same episodes, to the digit the results are reported in.
    a, b = (evaluate(p, "Foosball-Block-v0", episodes=4, seed=7) for p in (fast, slow))
    assert (a.success_rate, a.goals_against) == (b.success_rate, b.goals_against)
    assert a.mean_reward == pytest.approx(b.mean_reward, rel=1e-3, abs=1e-3)


def test_the_numpy_snapshot_without_normalisation(model_of):
    model = model_of(normalize=False)
    with th.no_grad():
        for p in model.policy.parameters():
            p.mul_(3.0)
    fast, slow = NumpySnapshot.of_model(model), PolicySnapshot.of_model(model)
    assert isinstance(fast, NumpySnapshot)
    obs = np.random.default_rng(5).normal(size=(16, fast.observation_size))
    np.testing.assert_allclose(fast(obs), slow(obs), atol=1e-5)


@pytest.mark.parametrize("kwargs", [{"use_sde": True}, {"algo": "sac"}])
def test_what_the_numpy_snapshot_cannot_copy_plays_in_pytorch(model_of, kwargs):
    snapshot = NumpySnapshot.of_model(model_of(**kwargs))
    assert isinstance(snapshot, PolicySnapshot)
