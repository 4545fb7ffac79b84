"""Self-play: the learner plays frozen copies of itself, replaced when it pulls ahead."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.env_util import make_vec_env  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize  # noqa: E402

from foosball_gym.training import (  # noqa: E402
    OpponentActionWrapper,
    PolicySnapshot,
    SelfPlayCallback,
    SelfPlayVecEnv,
)
from foosball_gym.training.selfplay.opponents import AGAINST_ANCHOR  # noqa: E402
from foosball_gym.training.selfplay.rule import game_result  # noqa: E402

ENV = "Foosball-KeeperVsKeeper-v0"


class RecordingSelfPlay(SelfPlayCallback):
    """Keeps a copy of the learner's weights at every replacement."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.learner_at_replacement = []

    def _add_snapshot(self, score, elo):
        super()._add_snapshot(score, elo)
        self.learner_at_replacement.append(
            {k: v.clone() for k, v in self.model.policy.state_dict().items()}
        )


def selfplay_model(vec_cls, n_envs=2, normalize=True):
    venv = make_vec_env(
        ENV,
        n_envs=n_envs,
        seed=0,
        wrapper_class=OpponentActionWrapper,
        vec_env_cls=vec_cls,
        env_kwargs={"stagnation_steps": 20},
    )
    venv = SelfPlayVecEnv(venv, lambda obs: np.zeros((len(obs), 2), np.float32), seed=0)
    if normalize:
        venv = VecNormalize(venv, norm_reward=False)
    return PPO(
        "MlpPolicy",
        venv,
        n_steps=128,
        batch_size=128,
        n_epochs=2,
        seed=0,
        device="cpu",
        policy_kwargs={"net_arch": [32, 32]},
    )


def test_opponent_is_replaced_by_a_snapshot_of_the_learner(tmp_path):
    model = selfplay_model(DummyVecEnv)
    initial = {k: v.clone() for k, v in model.policy.state_dict().items()}
    callback = RecordingSelfPlay(window=4, rule="net_score", threshold=-1.0, save_dir=tmp_path)
    model.learn(3000, callback=callback)
    assert callback.generation >= 1
    latest = callback.pool[-1]
    # The opponent's weights are the learner's at the moment of replacement ...
    for key, value in callback.learner_at_replacement[-1].items():
        assert np.array_equal(latest.policy.state_dict()[key].numpy(), value.numpy())
    # ... which had learnt: not the initial weights.
    assert any(
        not np.array_equal(initial[k].numpy(), v.numpy())
        for k, v in callback.learner_at_replacement[-1].items()
    )
    # The env plays it, and it carries the normalisation the learner used.
    selfplay_env = model.get_env().venv
    assert selfplay_env.pool[-1] is latest
    assert latest.obs_mean is not None
    # History and snapshots are on disk.
    history = (tmp_path / "history.json").read_text()
    assert f'"generation": {callback.generation}' in history
    assert (tmp_path / f"opponent_{callback.generation:04d}.pt").exists()
    reloaded = PolicySnapshot.load(tmp_path / f"opponent_{callback.generation:04d}.pt")
    assert reloaded.parameters_equal(latest.policy)


def test_no_replacement_while_the_learner_is_not_ahead():
    model = selfplay_model(DummyVecEnv)
    callback = SelfPlayCallback(window=4, threshold=0.99)
    model.learn(1500, callback=callback)
    assert callback.generation == 0 and len(callback.pool) == 1


def test_self_play_runs_with_subprocess_envs():
    model = selfplay_model(SubprocVecEnv)
    callback = SelfPlayCallback(window=2, rule="net_score", threshold=-1.0)
    try:
        model.learn(1500, callback=callback)
    finally:
        model.get_env().close()
    assert callback.generation >= 1 and callback.games >= 2


def test_opponents_of_all_envs_are_evaluated_in_one_batched_call():
    venv = make_vec_env(ENV, n_envs=4, seed=0, wrapper_class=OpponentActionWrapper)
    calls = []

    def opponent(obs):
        calls.append(obs.shape)
        return np.zeros((len(obs), 2), np.float32)

    env = SelfPlayVecEnv(venv, opponent, seed=0)
    env.reset()
    for _ in range(5):
        env.step(np.zeros((4, 2), np.float32))
    env.close()
    assert calls == [(4, 10)] * 5


def test_a_pool_of_opponents_is_drawn_from_per_episode():
    venv = make_vec_env(ENV, n_envs=6, seed=0, wrapper_class=OpponentActionWrapper)
    used = set()

    def make(k):
        def opponent(obs):
            used.add(k)
            return np.zeros((len(obs), 2), np.float32)

        return opponent

    env = SelfPlayVecEnv(venv, make(0), seed=1)
    env.set_pool([make(0), make(1), make(2)])
    env.reset()
    env.step(np.zeros((6, 2), np.float32))
    env.close()
    assert used == {0, 1, 2}


def test_the_opponent_acts_on_the_mirrored_observation():
    venv = make_vec_env(ENV, n_envs=1, seed=0, wrapper_class=OpponentActionWrapper)
    seen = []
    env = SelfPlayVecEnv(venv, lambda obs: seen.append(obs.copy()) or np.zeros((1, 2), np.float32))
    obs = env.reset()
    env.step(np.zeros((1, 2), np.float32))
    env.close()
    # The ball's x and y (indices 6, 7) are negated for the opponent.
    np.testing.assert_allclose(seen[0][0, 6:8], -obs[0, 6:8], atol=1e-6)


def test_game_result_counts_wins_losses_and_draws():
    assert game_result({"goals_for": 1, "goals_against": 0}) == 1
    assert game_result({"goals_for": 0, "goals_against": 2}) == -1
    assert game_result({"goals_for": 0, "goals_against": 0}) == 0


def test_snapshot_normalises_like_vecnormalize():
    model = selfplay_model(DummyVecEnv)
    model.learn(256)
    norm = model.get_env()
    snap = PolicySnapshot.of_model(model)
    raw = np.random.default_rng(0).normal(size=(3, 10)).astype(np.float32)
    np.testing.assert_allclose(snap.normalise(raw), norm.normalize_obs(raw), rtol=1e-5)
    batch = snap(raw)
    assert batch.shape == (3, 2) and np.all(np.abs(batch) <= 1)
    np.testing.assert_allclose(snap(raw[0]), batch[0], atol=1e-6)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"window": 0}, "window"),
        ({"threshold": 1.5}, "threshold"),
        ({"pool_size": 0}, "pool_size"),
    ],
)
def test_bad_self_play_settings_are_rejected(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SelfPlayCallback(**kwargs)


def test_a_share_of_games_is_played_against_the_scripted_anchor_and_left_out_of_the_rule():
    venv = make_vec_env(
        ENV,
        n_envs=4,
        seed=0,
        wrapper_class=OpponentActionWrapper,
        env_kwargs={"stagnation_steps": 20},
    )
    anchor = venv.env_method("scripted_opponent", indices=[0])[0]
    env = SelfPlayVecEnv(
        venv, lambda obs: np.zeros((len(obs), 2), np.float32), 0, anchor=anchor, anchor_share=0.5
    )
    model = PPO("MlpPolicy", env, n_steps=128, batch_size=128, n_epochs=1, seed=0, device="cpu")
    callback = SelfPlayCallback(window=1000, threshold=0.99)
    ended = []

    class Ends(SelfPlayCallback):
        def _on_step(self):
            ended.extend(
                bool(info.get(AGAINST_ANCHOR))
                for done, info in zip(self.locals["dones"], self.locals["infos"])
                if done
            )
            return True

    model.learn(3000, callback=[callback, Ends()])
    env.close()
    anchored = sum(ended)
    # Both kinds of game were played, about half each, and only the snapshot's count.
    assert 0.25 < anchored / len(ended) < 0.75, ended
    assert callback.games == len(ended) - anchored
    assert len(callback._anchor_goals) == anchored


@pytest.mark.parametrize("share", [-0.1, 1.0])
def test_a_bad_anchor_share_is_refused(share):
    venv = make_vec_env(ENV, n_envs=1, seed=0, wrapper_class=OpponentActionWrapper)
    anchor = venv.env_method("scripted_opponent", indices=[0])[0]
    with pytest.raises(ValueError, match=r"anchor_share must be in \[0, 1\)"):
        SelfPlayVecEnv(venv, lambda obs: obs[:, :2] * 0, anchor=anchor, anchor_share=share)
    with pytest.raises(ValueError, match="only with an anchor"):
        SelfPlayVecEnv(venv, lambda obs: obs[:, :2] * 0, anchor_share=0.5)
    venv.close()


def test_sampled_opponents_explore_as_the_learner_does_and_stay_so_after_a_restart(tmp_path):
    model = selfplay_model(DummyVecEnv)
    callback = SelfPlayCallback(
        window=4, rule="net_score", threshold=-1.0, save_dir=tmp_path, sampled=True
    )
    model.learn(1500, callback=callback)
    assert callback.generation >= 1
    obs = np.zeros((64, model.observation_space.shape[0]))
    for snap in callback.pool:
        assert not snap.deterministic
        # The same observation gets different actions, spread as the learner's are.
        actions = snap(obs)
        assert np.unique(actions[:, 0]).size > 32
        std = float(np.exp(snap.policy.log_std.detach().numpy()[0]))
        assert 0.5 * std < actions[:, 0].std() < 1.5 * std
    restarted = SelfPlayCallback(save_dir=tmp_path, sampled=True)
    restarted.init_callback(model)
    restarted._on_training_start()
    assert [s.generation for s in restarted.pool] == [callback.generation]
    assert not restarted.pool[0].deterministic


def test_opponents_act_on_their_mean_by_default():
    model = selfplay_model(DummyVecEnv)
    callback = SelfPlayCallback(window=4, rule="net_score", threshold=-1.0)
    model.learn(600, callback=callback)
    snap = callback.pool[-1]
    assert snap.deterministic
    actions = snap(np.zeros((8, model.observation_space.shape[0])))
    assert np.ptp(actions, axis=0).max() == 0.0


def test_a_stalled_run_says_so_once_and_falls_back_to_a_rule_that_can_fire(tmp_path, capsys):
    # A win rate of 99 % is never reached: the run stalls after 6 games and says so.
    model = selfplay_model(DummyVecEnv)
    callback = SelfPlayCallback(
        window=3, threshold=0.99, save_dir=tmp_path, stall_games=6, fallback="net_score"
    )
    model.learn(3000, callback=callback)
    out = capsys.readouterr().out
    assert callback.judge.games >= 6, "the run played too few games to judge"
    stalled = [line for line in out.splitlines() if "self-play stalled at" in line]
    # Said once for generation 0. Under net_score a later generation may stall too (a new
    # stall, said once more); the fallback is taken only the first time.
    assert len([line for line in stalled if "against generation 0 " in line]) == 1, out
    assert "no new opponent in 6 games against generation 0" in stalled[0]
    assert "judging by the net_score rule (0.2) from now on" in stalled[0]
    assert all(line.endswith("the rule stays") for line in stalled[1:]), out
    assert callback.stalls == len(stalled)
    lines = (tmp_path / "stalls.jsonl").read_text().splitlines()
    assert len(lines) == len(stalled)
    record = json.loads(lines[0])
    assert (record["generation"], record["since"], record["rule"]) == (0, 6, "win_rate")
    assert record["fallback"] == "net_score" and record["timesteps"] > 0
    assert all(json.loads(line)["rule"] == "net_score" for line in lines[1:])
    assert callback.judge.rule == "net_score"
