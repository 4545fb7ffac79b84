"""scripts/one_decision.py: Score with obstacles as one decision a serve, a model of which score."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from scripts_loader import load_script


@pytest.fixture(scope="module")
def one():
    return load_script("one_decision")


def test_a_decision_holds_its_slide_and_plays_its_spin_in_two_pieces(one):
    keeper = one.OneDecision((0.25, -0.3, 3, 0.6))
    obs = np.zeros(11, np.float32)
    actions = [keeper(obs) for _ in range(5)]
    assert [a[0] for a in actions] == pytest.approx([0.25] * 5)
    assert [a[1] for a in actions] == pytest.approx([-0.3, -0.3, -0.3, 0.6, 0.6])
    keeper.reset()
    assert keeper(obs)[1] == pytest.approx(-0.3)


def test_the_layout_is_the_ball_and_the_standing_rods_beside_it(one):
    names = list(one.LAYOUT) + ["home_keeper_slide_pos"]
    obs = np.array([-0.5, 0.02, 0.1, -0.05, 0.0, 0.3], np.float32)
    assert one.layout(names, obs) == pytest.approx(
        [-0.5, 0.02, 0.1, -0.05, 0.0, 0.08, -0.07, -0.02]
    )


def test_the_spins_kept_are_those_that_scored_most(one):
    decisions = np.array(
        [[0.1, -0.3, 4, 0.3], [0.5, -0.3, 4, 0.3], [0.2, 0.6, 8, 0.0], [-0.9, 0.6, 8, 0.0]],
        np.float32,
    )
    goals = np.array([1, 0, 1, 1], np.float32)
    assert one.best_spins(decisions, goals, 1).tolist() == [pytest.approx([0.6, 8, 0.0])]
    assert len(one.best_spins(decisions, goals, 5)) == 2
    assert one.most_scoring(decisions, goals) == pytest.approx([-0.9, 0.6, 8, 0.0], abs=1e-6)
    grid = one.candidates(one.best_spins(decisions, goals, 2), points=3)
    assert grid.shape == (6, 4) and sorted(set(grid[:, 0].tolist())) == [-1.0, 0.0, 1.0]


def test_the_model_learns_which_side_scores_and_picks_it(one):
    rng = np.random.default_rng(0)
    rows = rng.normal(size=(2000, 8)).astype(np.float32)
    decisions = np.column_stack(
        [rng.uniform(-1, 1, 2000), np.full(2000, -0.3), np.full(2000, 4.0), np.full(2000, 0.3)]
    ).astype(np.float32)
    # Scores where the slide's side matches the sign of the layout's second entry.
    goals = (np.sign(decisions[:, 0]) == np.sign(rows[:, 1])).astype(np.float32)
    model = one.OutcomeModel(rows, decisions)
    model.fit(rows, decisions, goals, epochs=15, tries=10)
    grid = one.candidates(np.array([[-0.3, 4.0, 0.3]], np.float32), points=21)
    for y in (-1.5, 1.5):
        row = np.zeros(8, np.float32)
        row[1] = y
        assert np.sign(model.best(row, grid)[0]) == np.sign(y)


def test_trials_play_each_decision_on_its_ball(one):
    spins = np.array([[0.0, 4.0, 0.0], [-0.3, 4.0, 0.3]], np.float32)
    rows, decisions, goals, steps = one.trials(10_000, 2, 3, spins)
    assert rows.shape == (6, 8) and decisions.shape == (6, 4) and goals.shape == (6,)
    assert set(goals.tolist()) <= {0.0, 1.0} and steps >= 6
    assert ((decisions[:, 1:] == spins[0]).all(1) | (decisions[:, 1:] == spins[1]).all(1)).all()
    env = gym.make(one.ENV_ID, **one.OPTIONS)
    try:
        for i, (decision, goal) in enumerate(zip(decisions, goals, strict=True)):
            ball = 10_000 + i // 3
            assert one.play(env, ball, decision)[0] == bool(goal)
        # A keeper whose foot never turns does not score.
        assert not one.play(env, 0, (0.0, 0.0, 4, 0.0))[0]
    finally:
        env.close()


def test_bad_options_are_refused(one, capsys):
    with pytest.raises(SystemExit):
        one.main(["--tries", "0"])
    assert "--tries must be at least 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        one.main(["--train-seed", "100", "--layouts", "10"])
    assert "overlap" in capsys.readouterr().err
    for bad in ("-0.3,4", "-0.3,4.5,0.3", "-2,4,0.3", "a,b,c"):
        with pytest.raises(SystemExit):
            one.main(["--spin", bad])
        assert "--spin" in capsys.readouterr().err


def test_rounds_narrow_the_spins_and_each_is_played(one, capsys):
    one.main(
        "--layouts 20 --tries 2 --rounds 2 --keep 2 --episodes 3 --epochs 1 --workers 1".split()
    )
    out = capsys.readouterr().out
    assert "round 1: 40 trials of 50 spins on balls 10000-10019" in out
    assert "round 2: 40 trials of 2 spins on balls 10020-10039" in out
    assert "model on 80 trials" in out
    assert out.count("the model's decision: ") == 2
    assert out.count("balls 3: scored ") == 3
    assert "one decision on every ball (v " in out


def test_the_model_seed_sets_the_first_weights(one):
    rows = np.zeros((4, 8), np.float32)
    decisions = np.zeros((4, 4), np.float32)
    first = [one.OutcomeModel(rows, decisions, seed).net[0].weight for seed in (1, 1, 2)]
    assert (first[0] == first[1]).all() and not (first[0] == first[2]).all()
