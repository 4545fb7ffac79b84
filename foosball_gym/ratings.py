"""Elo ratings from a round-robin of games, with their uncertainty.

Numpy only. The ratings are the maximum-likelihood fit of the Bradley-Terry model that Elo's
expected score assumes, P(i beats j) = 1 / (1 + 10^((R_j - R_i) / 400)), to every game at
once (as BayesElo and Ordo rate chess engines), not Elo's order-dependent online updates. A
draw counts half a win for each side. Every pair of players is also given one virtual draw,
a weak prior that keeps a player who won (or lost) every game at a finite rating. The
uncertainty is a bootstrap: each pair's games are resampled and the fit repeated.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ELO_SCALE = 400.0 / math.log(10.0)


@dataclass
class Ratings:
    """Ratings of ``players`` (Elo, ``anchor`` at 0) with 95 % bootstrap intervals."""

    players: list[str]
    elo: np.ndarray
    low: np.ndarray
    high: np.ndarray
    anchor: str


def _fit(wins: np.ndarray, anchor: int, iterations: int = 10_000, tol: float = 1e-10) -> np.ndarray:
    """Bradley-Terry strengths by Hunter's minorise-maximise iteration; Elo, anchor at 0.

    ``wins[i, j]`` is what i scored against j (draws as halves), prior included.
    """
    games = wins + wins.T
    scored = wins.sum(axis=1)
    gamma = np.ones(len(wins))
    for _ in range(iterations):
        denom = (games / (gamma[:, None] + gamma[None, :])).sum(axis=1)
        new = scored / denom
        new /= new[anchor]
        if np.max(np.abs(np.log(new) - np.log(gamma))) < tol:
            gamma = new
            break
        gamma = new
    return ELO_SCALE * np.log(gamma)


def fit_ratings(
    players: list[str],
    results: dict[tuple[int, int], tuple[int, int, int]],
    anchor: int = 0,
    bootstrap: int = 300,
    seed: int = 0,
) -> Ratings:
    """Ratings from ``results[(i, j)] = (wins of i, draws, wins of j)`` over their games.

    Raises:
        ValueError: fewer than two players, an index out of range, or a player who played
            no game.
    """
    n = len(players)
    if n < 2:
        raise ValueError(f"a league needs at least two players, got {n}")
    if not 0 <= anchor < n:
        raise ValueError(f"anchor must index a player (0..{n - 1}), got {anchor}")
    played = np.zeros(n, dtype=int)
    for (i, j), (won, drawn, lost) in results.items():
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise ValueError(f"bad pair {(i, j)} for {n} players")
        played[i] += won + drawn + lost
        played[j] += won + drawn + lost
    if (played == 0).any():
        idle = [players[k] for k in np.nonzero(played == 0)[0]]
        raise ValueError(f"no games played by {', '.join(idle)}")

    prior = np.full((n, n), 0.5)
    np.fill_diagonal(prior, 0.0)

    def table(sample: dict[tuple[int, int], tuple[int, int, int]]) -> np.ndarray:
        wins = prior.copy()
        for (i, j), (won, drawn, lost) in sample.items():
            wins[i, j] += won + drawn / 2
            wins[j, i] += lost + drawn / 2
        return wins

    elo = _fit(table(results), anchor)
    rng = np.random.default_rng(seed)
    draws = []
    for _ in range(bootstrap):
        sample = {}
        for pair, (won, drawn, lost) in results.items():
            total = won + drawn + lost
            sample[pair] = tuple(rng.multinomial(total, np.array([won, drawn, lost]) / total))
        draws.append(_fit(table(sample), anchor))
    low, high = np.percentile(draws, [2.5, 97.5], axis=0) if draws else (elo.copy(), elo.copy())
    return Ratings(list(players), elo, low, high, players[anchor])


def expected_score(elo_a: float, elo_b: float) -> float:
    """What a player rated ``elo_a`` is expected to score against one rated ``elo_b``."""
    return 1.0 / (1.0 + 10 ** ((elo_b - elo_a) / 400.0))
