"""Self-play of a residual learner, and self-play against rungs of the scripted ladder.

A learner trained with the option ``residual`` gives corrections to the scripted baseline;
its frozen copies must play as the baseline plus their correction wherever they are the
opponent (self-play's games, the gate, a league), since the opponent's side of the game takes
whole actions.
"""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from foosball_gym.cli import main  # noqa: E402
from foosball_gym.policy_io.task import residual_action  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.sb3.vec_env import make_env  # noqa: E402
from foosball_gym.training.selfplay.gate import ReplacementGate  # noqa: E402
from foosball_gym.training.selfplay.league import run_players  # noqa: E402
from foosball_gym.training.selfplay.opponents import AGAINST_ANCHOR, find_selfplay_env  # noqa: E402

ENV = "Foosball-KeeperVsKeeper-v0"
SHORT = {"stagnation_steps": 20}
SCALE = 0.5
CORRECTION = np.array([0.3, -0.6], dtype=np.float32)


def constant(correction):
    """A frozen 'snapshot' that always gives ``correction``, one row per observation."""

    def policy(obs):
        obs = np.asarray(obs)
        return np.tile(correction, (len(obs), 1)) if obs.ndim == 2 else correction.copy()

    return policy


def residual_config(**kwargs):
    config = TrainConfig(
        ENV, env_kwargs={**SHORT, "residual": SCALE}, n_envs=1, normalize=False, **kwargs
    )
    config.check()
    return config


@pytest.mark.parametrize("correction", [np.zeros(2, np.float32), CORRECTION])
def test_a_residual_learners_opponents_play_the_baseline_plus_their_correction(correction):
    venv = make_env(residual_config())
    find_selfplay_env(venv).set_pool([constant(correction)])
    # The same game with the opponent given as the environment's own: the scripted baseline
    # (acting on the mirrored observation, as it does for the home side) plus the correction,
    # in the single precision in which self-play's vectorised env passes opponents' actions.
    reference = gym.make(ENV, **SHORT, residual=SCALE)
    baseline = reference.unwrapped.scripted_policy()
    reference.unwrapped.set_opponent(
        lambda obs: residual_action(baseline(obs), SCALE, correction).astype(np.float32)
    )
    venv.seed(7)
    obs = venv.reset()
    expected, _ = reference.reset(seed=7)
    np.testing.assert_array_equal(obs[0], expected)
    mine = np.array([[0.2, -0.1]], dtype=np.float32)
    for _ in range(200):
        obs, _, dones, infos = venv.step(mine)
        expected, _, terminated, truncated, info = reference.step(mine[0])
        if dones[0]:
            assert terminated or truncated
            assert infos[0]["goals_for"] == info["goals_for"]
            break
        np.testing.assert_array_equal(obs[0], expected)
    venv.close()
    reference.close()


def test_the_scripted_share_of_games_meets_each_rung_asked_for():
    config = TrainConfig(
        ENV,
        env_kwargs=dict(SHORT),
        n_envs=2,
        normalize=False,
        selfplay_scripted_share=0.9,
        selfplay_scripted_levels=(0, 2),
    )
    config.check()
    venv = make_env(config)
    selfplay = find_selfplay_env(venv)
    met = []
    for k, anchor in enumerate(selfplay.anchors):

        def counting(obs, anchor=anchor, k=k):
            met.append(k)
            return anchor(obs)

        selfplay.anchors[k] = counting
    selfplay.set_pool([constant(np.zeros(2, np.float32))])
    venv.reset()
    ended = []
    for _ in range(600):
        _, _, dones, infos = venv.step(np.zeros((2, 2), np.float32))
        ended += [bool(info.get(AGAINST_ANCHOR)) for done, info in zip(dones, infos) if done]
    venv.close()
    # Both rungs played whole games, and those games are marked as the scripted side's.
    assert set(met) == {0, 1} and any(ended)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (
            {"selfplay_scripted_share": 0.5, "selfplay_scripted_levels": (1, 7)},
            "no scripted level 7",
        ),
        ({"selfplay_scripted_levels": (1,)}, "needs self-play and selfplay_scripted_share"),
        ({"selfplay_scripted_share": 0.5, "selfplay_scripted_levels": "12"}, "rung numbers"),
    ],
)
def test_bad_rungs_for_the_scripted_share_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(ENV, env_kwargs=dict(SHORT), **kwargs).check()


def test_the_command_line_refuses_rungs_that_are_not_numbers(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", ENV, "--selfplay-scripted-levels", "1,top"])
    assert exit_info.value.code == 2
    assert "rung numbers of the scripted ladder" in capsys.readouterr().err


def test_the_gate_plays_a_residual_learner_and_its_opponent_with_their_baseline():
    zero = constant(np.zeros(2, np.float32))
    gate = ReplacementGate(ENV, {**SHORT, "residual": SCALE}, games=4)
    plain = ReplacementGate(ENV, SHORT, games=4)
    env = gym.make(ENV, **SHORT)
    scripted = env.unwrapped.scripted_policy()
    env.close()
    try:
        # A residual learner that corrects nothing is the scripted team: its games are those
        # of the scripted team against itself, on the same serves.
        residual = gate.judge(zero, zero, timesteps=0)
        whole = plain.judge(scripted, scripted, timesteps=0)
    finally:
        gate.close()
        plain.close()
    assert residual.record() == whole.record()


def test_a_league_of_a_residual_run_plays_its_generations_with_their_baseline(tmp_path):
    run = tmp_path / "run"
    argv = ["train", ENV, "--timesteps", "1024", "--n-envs", "2", "--n-steps", "256"]
    argv += ["--batch-size", "128", "--eval-freq", "100000", "--eval-episodes", "1"]
    argv += ["--env-kwarg", "stagnation_steps=20", "--env-kwarg", f"residual={SCALE}"]
    argv += ["--selfplay-window", "2", "--selfplay-rule", "net_score"]
    argv += ["--selfplay-threshold", "-1", "--out", str(run), "--no-progress"]
    assert main(argv) == 0
    players, config = run_players(run)
    assert "residual" not in config["env_kwargs"]
    assert json.loads((run / "config.json").read_text())["env_kwargs"]["residual"] == SCALE
    env = gym.make(ENV, **config["env_kwargs"])
    obs, _ = env.reset(seed=0)
    baseline = env.unwrapped.scripted_policy()
    env.close()
    for player in players[:-1]:
        correction = player.policy.policy(obs)
        expected = residual_action(baseline(obs), SCALE, correction)
        np.testing.assert_allclose(player.policy(obs), expected, atol=1e-6)
    assert main(["league", str(run), "--games", "2", "--out", str(tmp_path)]) == 0
    assert "residual" not in json.loads((tmp_path / "league.json").read_text())["env_kwargs"]


def test_a_policy_trained_with_a_scale_for_each_joint_plays_the_whole_action():
    from foosball_gym.training.loading.loader import whole_action_policy

    scales = [0.5, 0.0]
    player, options = whole_action_policy(constant(CORRECTION), ENV, {**SHORT, "residual": scales})
    assert options == SHORT
    env = gym.make(ENV, **SHORT)
    obs, _ = env.reset(seed=1)
    baseline = env.unwrapped.scripted_policy()
    env.close()
    expected = np.clip(np.asarray(baseline(obs)) + np.array(scales) * CORRECTION, -1, 1)
    np.testing.assert_allclose(player(obs), expected, atol=1e-7)
    assert player(obs)[1] == np.float64(baseline(obs)[1])
