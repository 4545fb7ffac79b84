"""Elo ratings from round-robin results: the fit recovers known strengths, with intervals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from foosball_gym.ratings import expected_score, fit_ratings


def simulate(true_elo, games, draw_share, rng):
    """Round-robin results of players whose expected scores follow ``true_elo``."""
    results = {}
    n = len(true_elo)
    for i in range(n):
        for j in range(i + 1, n):
            score = expected_score(true_elo[i], true_elo[j])
            # Draws take from both sides alike, so the expected score stays Elo's.
            draw = draw_share * 2 * min(score, 1 - score)
            win = score - draw / 2
            results[(i, j)] = tuple(rng.multinomial(games, [win, draw, 1 - win - draw]))
    return results


def test_the_fit_recovers_known_ratings_within_its_intervals():
    true = np.array([0.0, 120.0, 250.0, -200.0, 400.0])
    names = [f"p{i}" for i in range(len(true))]
    ratings = fit_ratings(names, simulate(true, 400, 0.5, np.random.default_rng(3)))
    assert ratings.anchor == "p0" and ratings.elo[0] == 0
    # The prior's virtual draws pull the extremes in a little; 400 games a pair outweigh them.
    assert np.abs(ratings.elo - true).max() < 40
    assert np.all(ratings.low[1:] <= true[1:]) and np.all(true[1:] <= ratings.high[1:])
    assert np.all(ratings.high[1:] - ratings.low[1:] < 150)
    assert list(np.argsort(ratings.elo)) == list(np.argsort(true))


def test_fewer_games_give_wider_intervals():
    true = np.array([0.0, 200.0, 100.0])
    names = ["a", "b", "c"]
    rng = np.random.default_rng(0)
    few = fit_ratings(names, simulate(true, 10, 0.3, rng))
    many = fit_ratings(names, simulate(true, 1000, 0.3, rng))
    assert (few.high - few.low)[1:].min() > (many.high - many.low)[1:].max()


def test_a_player_who_won_everything_has_a_finite_rating_above_the_rest():
    results = {(0, 1): (0, 5, 0), (0, 2): (0, 0, 10), (1, 2): (0, 0, 10)}
    ratings = fit_ratings(["a", "b", "c"], results)
    assert all(math.isfinite(x) for x in ratings.elo)
    assert ratings.elo[2] > ratings.elo[0] + 200 and ratings.elo[1] == pytest.approx(0, abs=1)


def test_the_anchor_is_rated_zero():
    results = {(0, 1): (7, 2, 1)}
    ratings = fit_ratings(["a", "b"], results, anchor=1)
    assert ratings.anchor == "b" and ratings.elo[1] == 0 and ratings.elo[0] > 0


@pytest.mark.parametrize(
    "players, results, anchor, message",
    [
        (["a"], {}, 0, "at least two players"),
        (["a", "b"], {(0, 1): (1, 0, 0)}, 2, "anchor must index a player"),
        (["a", "b", "c"], {(0, 1): (1, 0, 0)}, 0, "no games played by c"),
        (["a", "b"], {(0, 0): (1, 0, 0)}, 0, "bad pair"),
    ],
)
def test_bad_leagues_are_refused(players, results, anchor, message):
    with pytest.raises(ValueError, match=message):
        fit_ratings(players, results, anchor=anchor)
