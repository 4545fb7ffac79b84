"""scripts/aim_windows.py: which held aims score on a ball whose straight lane is shut."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scripts_loader import load_script

OPTIONS = {
    "ball_start": "resting",
    "obstacles": True,
    "slide_around_ball": 0.015,
    "slide_skip": 0.009,
}


@pytest.fixture(scope="module")
def aims():
    return load_script("aim_windows")


def test_windows_are_the_runs_of_neighbouring_hits(aims):
    assert aims.windows([]) == []
    assert aims.windows([False, False]) == []
    assert aims.windows([True, True, False, True, False, False, True, True, True]) == [2, 1, 3]


def test_a_held_slide_is_an_aim_only_when_the_slide_is_read_around_the_ball(aims):
    aims.check_options(OPTIONS)
    with pytest.raises(ValueError, match="slide_around_ball"):
        aims.check_options({"ball_start": "resting", "obstacles": True})
    with pytest.raises(ValueError, match="obstacles=True"):
        aims.check_options({**OPTIONS, "obstacles": False})


def test_a_keeper_that_never_swings_scores_with_no_held_aim(aims):
    seen = []

    def still(obs):
        seen.append(obs)
        return np.array([0.7, 0.0], np.float32)

    resets = []
    env = gym.make("Foosball-Score-v0", **OPTIONS)
    hits = aims.scan(still, lambda: resets.append(1), env, seed=1, grid=np.array([-0.5, 0.5]))
    env.close()
    assert hits.tolist() == [False, False]
    assert len(resets) == 2 and seen


class OneStepBall:
    """Scores in one step when the slide it is given is above 0; records what it is given."""

    def __init__(self):
        self.resets, self.actions = [], []

    def reset(self, seed=None):
        self.resets.append(seed)
        return np.zeros(11, np.float32), {}

    def step(self, action):
        self.actions.append(np.asarray(action).tolist())
        return np.zeros(11, np.float32), 0.0, True, False, {"goal": int(action[0] > 0)}


def test_each_held_value_is_played_on_the_ball_and_its_goal_counted(aims):
    def keeper(obs):
        return np.array([0.3, -0.25], np.float32)

    env = OneStepBall()
    hits = aims.scan(keeper, None, env, seed=7, grid=np.array([-0.5, 0.0, 0.75]))
    assert hits.tolist() == [False, False, True]
    # The same ball each time, the slide the held value and the spin the keeper's own.
    assert env.resets == [7, 7, 7]
    assert env.actions == [[-0.5, -0.25], [0.0, -0.25], [0.75, -0.25]]
