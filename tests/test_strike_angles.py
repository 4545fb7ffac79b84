"""scripts/strike_angles.py: a keeper's strikes in keeper against keeper and the strike before
each goal, the figures keeper-vs-keeper.md compares the runs by."""

from __future__ import annotations

import gymnasium as gym
import pytest
from scripts_loader import load_script

SERVES = 12


@pytest.fixture(scope="module")
def angles():
    return load_script("strike_angles")


@pytest.fixture(scope="module")
def rungs(angles):
    env = gym.make(angles.ENV_ID)
    try:
        return env.unwrapped.scripted_level(None), env.unwrapped.scripted_level(1)
    finally:
        env.close()


def test_the_kicking_keeper_strikes_straight_and_the_attacking_one_banks_its_goals(angles, rungs):
    attacking, kicking = rungs
    straight = angles.play(kicking, {}, "scripted:1", SERVES, seed=0)
    assert [s.seed for s in straight] == list(range(SERVES))
    strikes = [a for s in straight for a in s.strikes]
    assert strikes and all(abs(a) < angles.AIMED for a in strikes)
    banked = angles.play(attacking, {}, "scripted:1", SERVES, seed=0)
    goals = [s for s in banked if s.goal == 1]
    # Its goals against the kicking keeper are banks off the side wall, struck at about 33
    # degrees, into the corner beside the goal (docs/results/ladder.md).
    assert goals and all(25 < abs(s.strikes[-1]) < 40 for s in goals)
    text = angles.summary(banked)
    assert f"goals for {len(goals)}, against 0" in text
    assert "last strike before each goal scored" in text


def test_only_a_scripted_rung_is_an_opponent(angles, capsys):
    with pytest.raises(SystemExit):
        angles.main(["scripted", "--opponent", "runs/somewhere"])
    assert "--opponent must be scripted or scripted:N" in capsys.readouterr().err
