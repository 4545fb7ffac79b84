"""The self-play gate: a replacement stands only where the learner's mean earns it."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

import gymnasium as gym  # noqa: E402
from stable_baselines3.common.vec_env import DummyVecEnv  # noqa: E402
from test_selfplay import ENV, selfplay_model  # noqa: E402

from foosball_gym import load_policy  # noqa: E402
from foosball_gym.training import PolicySnapshot, SelfPlayCallback  # noqa: E402
from foosball_gym.training.config import TrainConfig  # noqa: E402
from foosball_gym.training.selfplay.gate import (  # noqa: E402
    GateVerdict,
    ReplacementGate,
    _on_mean,
    gate_passes,
)

SHORT = {"stagnation_steps": 20}


def idle(obs):
    return np.zeros(2, np.float32)


@pytest.mark.parametrize(
    "wins, losses, learner, opponent, passes",
    [
        (2, 1, (1, 0), (0, 0), True),
        (1, 2, (5, 0), (0, 0), False),  # lost more head-to-head
        (0, 0, (0, 2), (0, 5), True),  # level head-to-head, conceded less to the scripted side
        (3, 1, (1, 1), (2, 2), False),  # equal goal difference, fewer goals
        (3, 1, (2, 2), (1, 1), True),  # equal goal difference, more goals
        (3, 1, (0, 3), (1, 2), False),
        (0, 0, (0, 0), (0, 0), False),  # a copy of the opponent does not pass
    ],
)
def test_the_gate_asks_for_the_duel_held_and_the_scripted_side_played_better(
    wins, losses, learner, opponent, passes
):
    assert gate_passes(wins, losses, learner, opponent) is passes


def test_the_gate_plays_the_duel_and_both_against_the_scripted_side_on_the_same_serves():
    env = gym.make(ENV, **SHORT)
    # The kicking keeper (the scripted side is the attacking keeper, the top of the ladder).
    kicking = env.unwrapped.scripted_level(1)
    env.close()
    gate = ReplacementGate(ENV, SHORT, games=6)
    try:
        strong = gate.judge(kicking, idle, timesteps=0)
        weak = gate.judge(idle, kicking, timesteps=0)
    finally:
        gate.close()
    assert strong.wins + strong.draws + strong.losses == 6
    # The kicking keeper beats an idle one and concedes less to the scripted side than the
    # idle one does on the same serves.
    assert strong.wins > strong.losses
    assert strong.goals_against < strong.opponent_goals_against and strong.passed
    # The other way round: the idle learner loses the duel and concedes more; refused.
    assert weak.losses > weak.wins and weak.goals_against > 0
    assert (weak.goals_for, weak.goals_against) == (
        strong.opponent_goals_for,
        strong.opponent_goals_against,
    )
    assert not weak.passed


def test_a_sampling_opponent_is_judged_on_its_mean_and_left_sampling():
    model = selfplay_model(DummyVecEnv)
    opponent = PolicySnapshot.of_model(model, deterministic=False)
    learner = PolicySnapshot.of_model(model, deterministic=True)
    gate = ReplacementGate(ENV, SHORT, games=4)
    try:
        first = gate.judge(learner, opponent, timesteps=100)
        again = gate.judge(learner, opponent, timesteps=100)
    finally:
        gate.close()
    # Both on the same weights' mean, served alike: the same games, whatever the sampling.
    assert first == again
    obs = np.random.default_rng(0).normal(size=(64, learner.observation_size))
    np.testing.assert_array_equal(_on_mean(opponent)(obs), learner(obs))
    assert not np.array_equal(opponent(obs), learner(obs))  # the opponent itself samples
    assert opponent.deterministic is False


@pytest.mark.parametrize("games, message", [(1, "at least 2"), (-4, "at least 2")])
def test_a_gate_of_too_few_games_is_refused(games, message):
    with pytest.raises(ValueError, match=message):
        ReplacementGate(ENV, SHORT, games)
    with pytest.raises(ValueError, match="selfplay_gate"):
        TrainConfig(ENV, selfplay_gate=games).check()


def test_a_gate_needs_self_play():
    with pytest.raises(ValueError, match="needs self-play|without self-play"):
        TrainConfig("Foosball-Block-v0", selfplay_gate=10).check()


class ScriptedVerdicts:
    """A gate whose verdicts are given in advance, to watch what the callback does with them."""

    def __init__(self, passes):
        self.passes = list(passes)
        self.calls = []

    def judge(self, learner, opponent, timesteps):
        self.calls.append((learner.deterministic, opponent.generation))
        ok = self.passes.pop(0) if self.passes else False
        return GateVerdict(timesteps, 4, 2 if ok else 0, 2, 0, int(ok), 0, 0, 0)

    def close(self):
        pass


# No config.json beside this bare callback's files: the model records no physics.
@pytest.mark.filterwarnings("ignore::foosball_gym.training.run_dir.physics.PhysicsMismatchWarning")
def test_a_refused_replacement_keeps_the_opponent_and_a_passed_one_is_saved_as_a_model(
    tmp_path,
):
    model = selfplay_model(DummyVecEnv)
    gate = ScriptedVerdicts([False, True, False, False])
    callback = SelfPlayCallback(
        window=4, rule="net_score", threshold=-1.0, save_dir=tmp_path, gate=gate
    )
    model.learn(3000, callback=callback)
    assert len(gate.calls) >= 4
    # Only the one verdict that passed made a generation.
    assert callback.generation == 1
    assert all(deterministic for deterministic, _ in gate.calls)
    verdicts = [json.loads(line) for line in (tmp_path / "gate.jsonl").read_text().splitlines()]
    assert [v["passed"] for v in verdicts[:4]] == [False, True, False, False]
    assert [v["generation"] for v in verdicts[:3]] == [0, 0, 1]
    # The generation is a model foosball eval can read, with the snapshot's weights.
    loaded = load_policy(tmp_path / "generation_0001.zip")
    assert loaded.policy.parameters_equal(callback.pool[-1].policy)
    np.testing.assert_allclose(loaded.policy.obs_mean, callback.pool[-1].obs_mean)
