"""worker_rollouts: each process that steps environments plays its share's whole rollout with a
copy of the policy. The rollout it fills is SB3's own (same observations, actions, rewards,
values, advantages and statistics where the noise is the same), the policy's copy is the policy,
a run with it trains, resumes and loads as any other, and what it cannot play is refused. In
self-play the workers play the opponents too, the same whatever the split."""

from __future__ import annotations

import json
import zipfile
from copy import deepcopy

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import torch as th  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.callbacks import BaseCallback, CallbackList  # noqa: E402

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.policy_io.around_ball import AroundBallPlayer  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.loading.sb3_load import sb3_objects  # noqa: E402
from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot  # noqa: E402
from foosball_gym.training.sb3.model import RolloutPPO, build_model  # noqa: E402
from foosball_gym.training.sb3.numpy_policy import NumpyPolicy  # noqa: E402
from foosball_gym.training.sb3.numpy_snapshot import NumpySnapshot  # noqa: E402
from foosball_gym.training.sb3.vec_env import make_env  # noqa: E402
from foosball_gym.training.selfplay.opponents import (  # noqa: E402
    AGAINST_ANCHOR,
    find_selfplay_env,
)


def _model(config: TrainConfig) -> tuple[object, object]:
    config.check()
    venv = make_env(config)
    return build_model(config, venv, None), venv


def _quiet(model: object) -> None:
    """The policy's noise far below a float32 step of its mean: both loops play the mean, so
    their rollouts can be compared whatever generator draws the noise."""
    with th.no_grad():
        model.policy.log_std.fill_(-30.0)


def _collect(model: object, venv: object, steps: int) -> None:
    model._setup_learn(steps, CallbackList([]))
    callback = CallbackList([])
    callback.init_callback(model)
    assert model.collect_rollouts(venv, callback, model.rollout_buffer, model.n_steps)


@pytest.mark.parametrize(
    ("vec_env", "normalize"),
    # Normalised with the statistics held still (VecNormalize not learning): SB3 updates them
    # every step, the workers after the rollout (the next test).
    [("dummy", True), ("batched", True), ("batched", False)],
)
def test_a_rollout_played_in_the_workers_is_the_one_sb3_plays(vec_env, normalize):
    kwargs = dict(
        n_envs=4,
        n_steps=96,
        batch_size=64,
        seed=3,
        vec_env=vec_env,
        normalize=normalize,
        normalize_reward=normalize,
        learner="torch",
    )
    rollouts = []
    for workers in (False, True):
        model, venv = _model(TrainConfig("Foosball-Block-v0", worker_rollouts=workers, **kwargs))
        try:
            assert isinstance(model, RolloutPPO) == workers
            if normalize:
                venv.training = False
                venv.obs_rms.mean[:] = 0.1
                venv.obs_rms.var[:] = 4.0
                venv.ret_rms.var = 9.0
            _quiet(model)
            _collect(model, venv, model.n_steps * 4)
            buf = model.rollout_buffer
            rollouts.append(
                [
                    buf.observations,
                    buf.actions,
                    buf.rewards,
                    buf.episode_starts,
                    buf.values,
                    # (not the log-probabilities: with the noise below float32's step, SB3's
                    # action minus its mean is 0, the drawn noise is not; the policy's test
                    # compares them)
                    buf.advantages,
                    model._last_obs,
                    *([venv.returns] if normalize else []),
                ]
            )
            assert model.num_timesteps == 4 * 96
            assert len(model.ep_info_buffer) > 0  # episodes ended and were counted
        finally:
            venv.close()
    sb3, ours = rollouts
    # Episodes ended within the rollout, so resets and the truncation bootstrap took part.
    assert sb3[3][1:].sum() >= 2
    for expected, got in zip(sb3, ours, strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-4)


def test_the_statistics_take_in_every_observation_and_return_after_the_rollout():
    config = TrainConfig("Foosball-Block-v0", n_envs=4, n_steps=64, batch_size=64, seed=2)
    model, venv = _model(config)
    try:
        seen = []

        class Record(BaseCallback):
            def _on_step(self) -> bool:
                # The callbacks see the statistics the rollout was normalised with.
                assert venv.obs_rms.count == before[0].count
                seen.append(venv.unnormalize_obs(self.locals["new_obs"]))
                return True

        model._setup_learn(256, CallbackList([]))  # resets the environments
        # Wide statistics, so that no observation is clipped and each can be recovered.
        venv.obs_rms.mean[:], venv.obs_rms.var[:] = 0.1, 16.0
        before = deepcopy(venv.obs_rms), deepcopy(venv.ret_rms)
        callback = CallbackList([Record()])
        callback.init_callback(model)
        first = venv.unnormalize_obs(model._last_obs)
        assert model.collect_rollouts(venv, callback, model.rollout_buffer, model.n_steps)
        # Every observation the environments gave in the rollout (its new_obs, step by step,
        # those after a reset included), and nothing else: SB3's VecNormalize takes the same.
        expected = deepcopy(before[0])
        expected.update(np.concatenate(seen))
        np.testing.assert_allclose(venv.obs_rms.mean, expected.mean, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(venv.obs_rms.var, expected.var, rtol=1e-5, atol=1e-6)
        assert venv.obs_rms.count == pytest.approx(before[0].count + 64 * 4)
        assert venv.ret_rms.count == pytest.approx(before[1].count + 64 * 4)
        assert first.shape == seen[0].shape
    finally:
        venv.close()


def test_the_numpy_policy_is_the_policy():
    model, venv = _model(
        TrainConfig("Foosball-Block-v0", n_envs=1, batch_size=128, vec_env="dummy")
    )
    try:
        policy = model.policy
        with th.no_grad():
            policy.log_std.fill_(-0.7)
        copy = NumpyPolicy.of(policy, model.action_space)
        obs = np.random.default_rng(0).normal(size=(5, *model.observation_space.shape))
        rngs = [np.random.default_rng([1, i]) for i in range(5)]
        batch = np.zeros((5, obs.shape[1]), np.float32)
        actions, values, log_probs = copy.act(obs, rngs, slice(0, 5), batch)
        with th.no_grad():
            value, log_prob, _ = policy.evaluate_actions(
                th.as_tensor(obs, dtype=th.float32), th.as_tensor(actions)
            )
            mean = policy.get_distribution(th.as_tensor(obs, dtype=th.float32)).distribution.mean
        np.testing.assert_allclose(values, value.numpy()[:, 0], rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(log_probs, log_prob.numpy(), rtol=1e-5, atol=1e-4)
        # The draws spread around the mean by the policy's own deviation.
        draws = np.stack(
            [
                copy.act(
                    obs, [np.random.default_rng([s, i]) for i in range(5)], slice(0, 5), batch
                )[0]
                for s in range(400)
            ]
        )
        np.testing.assert_allclose(draws.mean(axis=0), mean.numpy(), atol=0.06)
        np.testing.assert_allclose(draws.std(axis=0), np.exp(-0.7), rtol=0.12)
    finally:
        venv.close()


def test_a_run_with_worker_rollouts_trains_resumes_and_loads(tmp_path):
    pytest.importorskip("jax")
    run = tmp_path / "run"
    small = ["--n-envs", "4", "--n-steps", "64", "--batch-size", "64", "--no-progress"]
    small += ["--lr-schedule", "constant"]
    small += ["--eval-freq", "100000", "--eval-episodes", "1", "--checkpoint-freq", "256"]
    argv = ["train", "Foosball-Block-v0", "--out", str(run), "--worker-rollouts", *small]
    assert main([*argv, "--timesteps", "512"]) == 0
    assert json.loads((run / "config.json").read_text())["worker_rollouts"] is True
    first = PPO.load(run / "model.zip", device="cpu", custom_objects=sb3_objects(run / "model.zip"))
    assert main(["train", "--resume", str(run), "--timesteps", "1024", "--no-progress"]) == 0
    second = PPO.load(
        run / "model.zip", device="cpu", custom_objects=sb3_objects(run / "model.zip")
    )
    assert second.num_timesteps == 1024
    moved = [
        not th.equal(a, b)
        for a, b in zip(first.policy.parameters(), second.policy.parameters(), strict=True)
    ]
    assert any(moved)  # the resumed run went on learning


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"algo": "sac"}, "sac learns from a replay buffer"),
        ({"use_sde": True}, "use_sde's noise is drawn in the training process"),
        ({"vec_env": "subproc"}, "needs vec_env batched or dummy"),
    ],
)
def test_what_worker_rollouts_cannot_play_is_refused(bad, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig("Foosball-Block-v0", worker_rollouts=True, **bad).check()


def test_a_self_play_run_in_the_workers_replaces_its_opponent_and_resumes(tmp_path):
    pytest.importorskip("jax")
    run = tmp_path / "run"
    small = ["--n-envs", "4", "--n-steps", "64", "--batch-size", "64", "--no-progress"]
    small += ["--eval-freq", "100000", "--eval-episodes", "1", "--checkpoint-freq", "512"]
    # A rule that replaces the opponent after every 4 games, and games a still ball ends.
    rule = ["--selfplay-rule", "net_score", "--selfplay-threshold", "-1", "--selfplay-window", "4"]
    argv = ["train", "Foosball-KeeperVsKeeper-v0", "--self-play", *rule, *small, "--out", str(run)]
    argv += ["--env-kwarg", "stagnation_steps=20", "--lr-schedule", "constant"]
    assert main([*argv, "--timesteps", "1536"]) == 0
    assert json.loads((run / "config.json").read_text())["worker_rollouts"] is True
    with zipfile.ZipFile(run / "model.zip") as saved:  # the pool's copies are not saved
        assert "_numpy_pool" not in saved.read("data").decode()
    history = json.loads((run / "selfplay" / "history.json").read_text())
    generations = [entry["generation"] for entry in history]
    assert max(generations) >= 1
    assert main(["train", "--resume", str(run), "--timesteps", "2048", "--no-progress"]) == 0
    resumed = json.loads((run / "selfplay" / "history.json").read_text())
    assert max(entry["generation"] for entry in resumed) > max(generations)


@pytest.mark.parametrize(
    ("bad", "message"),
    [
        ({"env_kwargs": {"residual": 0.5}}, "a residual learner's corrections are made whole"),
        ({"selfplay_sampled": True}, "selfplay_sampled's draws are made in the training"),
    ],
)
def test_what_worker_rollouts_cannot_play_in_self_play_is_refused(bad, message):
    config = TrainConfig("Foosball-KeeperVsKeeper-v0", self_play=True, **bad)
    config.check()
    assert config.worker_rollouts is False  # the default leaves it off
    with pytest.raises(ValueError, match=message):
        TrainConfig(
            "Foosball-KeeperVsKeeper-v0", self_play=True, worker_rollouts=True, **bad
        ).check()


def test_self_play_plays_its_rollouts_in_the_workers_by_default():
    config = TrainConfig("Foosball-FullGame-v0", self_play=True)
    config.check()
    assert config.worker_rollouts is True


def _self_play(vec_env: str, workers: bool, **kwargs: object) -> tuple[list[np.ndarray], int]:
    """One rollout of keeper against keeper, the policy's noise turned down: the buffer, the
    opponents assigned at its end, and the games that ended against a scripted anchor."""
    config = TrainConfig(
        "Foosball-KeeperVsKeeper-v0",
        n_envs=4,
        n_steps=200,
        batch_size=100,
        seed=3,
        vec_env=vec_env,
        self_play=True,
        worker_rollouts=workers,
        normalize=False,
        normalize_reward=False,
        learner="torch",
        env_kwargs={"stagnation_steps": 60},  # a still ball ends the game in a second
        **kwargs,
    )
    model, venv = _model(config)
    anchored = []

    class Count(BaseCallback):
        def _on_step(self) -> bool:
            for done, info in zip(self.locals["dones"], self.locals["infos"], strict=True):
                anchored.append(bool(done and info.get(AGAINST_ANCHOR)))
            return True

    try:
        model._setup_learn(800, CallbackList([]))
        _quiet(model)
        selfplay = find_selfplay_env(venv)
        if kwargs.get("selfplay_pool"):
            with th.no_grad():  # a snapshot that moves, of a policy that is not the learner's
                for p in model.policy.parameters():
                    p.add_(th.linspace(-0.5, 0.5, p.numel()).reshape(p.shape))
            selfplay.set_pool([PolicySnapshot.of_model(model)])
            _quiet(model)
        callback = CallbackList([Count()])
        callback.init_callback(model)
        assert model.collect_rollouts(venv, callback, model.rollout_buffer, model.n_steps)
        buf = model.rollout_buffer
        arrays = [buf.observations, buf.actions, buf.rewards, buf.episode_starts, buf.advantages]
        return [*arrays, model._last_obs, selfplay._assigned.copy()], sum(anchored)
    finally:
        venv.close()


def test_a_self_play_rollout_played_in_the_workers_is_the_one_sb3_plays():
    # The first opponent holds still, so both loops face the same one.
    (sb3, _), (ours, _) = (_self_play("batched", workers) for workers in (False, True))
    assert sb3[3][1:].sum() >= 2  # games ended within the rollout
    for expected, got in zip(sb3, ours, strict=True):
        np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-4)


def test_self_play_in_the_workers_does_not_depend_on_the_split():
    # A snapshot in the pool and two rungs of the ladder drawn for half of the games.
    mixed = dict(selfplay_pool=1, selfplay_scripted_share=0.5, selfplay_scripted_levels=(0, 1))
    (batched, anchored), (alone, anchored_alone) = (
        _self_play(vec_env, True, **mixed) for vec_env in ("batched", "dummy")
    )
    assert batched[3][1:].sum() >= 2
    assert anchored == anchored_alone >= 1  # games against an anchor were counted as such
    for expected, got in zip(alone, batched, strict=True):
        np.testing.assert_array_equal(got, expected)


def test_a_snapshot_in_numpy_acts_as_the_snapshot():
    model, venv = _model(
        TrainConfig("Foosball-KeeperVsKeeper-v0", n_envs=1, batch_size=128, vec_env="dummy")
    )
    try:
        venv.obs_rms.mean[:], venv.obs_rms.var[:] = 0.2, 3.0
        snapshot = PolicySnapshot.of_model(model)
        copy = NumpySnapshot.of_snapshot(snapshot)
        assert isinstance(copy, NumpySnapshot)
        obs = np.random.default_rng(0).normal(size=(6, *model.observation_space.shape)) * 3
        np.testing.assert_allclose(copy(obs), snapshot(obs), atol=1e-5)
        sampling = PolicySnapshot.of_model(model, deterministic=False)
        assert NumpySnapshot.of_snapshot(sampling) is sampling  # its draws are PyTorch's
    finally:
        venv.close()


def test_a_snapshot_sliding_around_the_ball_keeps_its_band_in_the_workers():
    config = TrainConfig(
        "Foosball-KeeperVsKeeper-v0",
        n_envs=2,
        batch_size=128,
        vec_env="dummy",
        self_play=True,
        worker_rollouts=True,
        env_kwargs={"slide_around_ball": 0.04},
    )
    model, venv = _model(config)
    try:
        selfplay = find_selfplay_env(venv)
        selfplay.set_pool([PolicySnapshot.of_model(model)])
        (played,) = selfplay.pool
        assert isinstance(played, AroundBallPlayer)
        # The worker's copy computes the policy in NumPy, inside the same conversion.
        (copy,) = model._playable_pool(selfplay.pool)
        assert isinstance(copy, AroundBallPlayer) and isinstance(copy.player, NumpySnapshot)
        obs = np.random.default_rng(0).normal(size=(6, *model.observation_space.shape)) * 0.05
        np.testing.assert_allclose(copy(obs), played(obs), atol=1e-4)
        # The conversion is there: the slide sent is not the policy's own.
        assert not np.allclose(copy(obs)[:, 0], copy.player(obs)[:, 0], atol=1e-3)
    finally:
        venv.close()
