"""scripts/aim_windows.py: which held aims score on a ball whose straight lane is shut."""

from __future__ import annotations

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
    hits = aims.scan(still, lambda: resets.append(1), OPTIONS, seed=1, grid=np.array([-0.5, 0.5]))
    # A keeper whose feet never swing strikes nothing: no held aim scores.
    assert hits.tolist() == [False, False]
    assert len(resets) == 2 and seen


def test_each_held_value_is_played_on_the_ball_and_its_goal_counted(aims, monkeypatch):
    played = []

    class Result:
        def __init__(self, scored):
            self.success_rate = 1.0 if scored else 0.0

    def fake_evaluate(policy, env_id, env_kwargs, episodes, seed):
        action = policy(np.zeros(11, np.float32))
        played.append((env_id, seed, episodes, action.tolist()))
        return Result(scored=action[0] > 0)

    monkeypatch.setattr(aims, "evaluate", fake_evaluate)

    def keeper(obs):
        return np.array([0.3, -0.25], np.float32)

    hits = aims.scan(keeper, None, OPTIONS, seed=7, grid=np.array([-0.5, 0.0, 0.75]))
    assert hits.tolist() == [False, False, True]
    # The slide is the held value and the spin the keeper's own, ball after ball the same one.
    assert played == [
        ("Foosball-Score-v0", 7, 1, [-0.5, -0.25]),
        ("Foosball-Score-v0", 7, 1, [0.0, -0.25]),
        ("Foosball-Score-v0", 7, 1, [0.75, -0.25]),
    ]
