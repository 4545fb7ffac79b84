"""Where a full-game learner from nothing starts: the action 0 of its action space, with the
exploration noise of its first rollouts, against the scripted ladder.

A policy network starts with its mean action near 0, and ``builtin:full-game-scratch`` reads
every slide around the ball (``slide_around_ball``), so its starting team brings a figurine of
every rod under the ball, feet down, and its exploring team adds Gaussian noise of the policy's
starting spread. This plays that team, with and without noise, in continuous one-minute
matches (seeds 0..N-1) against rungs of the ladder and prints the goals of each condition; then
the settings file's noise on some entries of the action only.

    python benchmarks/full_game_start.py [--matches 10] [--opponents scripted:0 scripted:1]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from foosball_gym.evaluation import evaluate
from foosball_gym.training.config_file import read_config_file

# Standard deviations as fractions of the action's range: none, then exp(log_std_init) for
# log_std_init -5, -3.5, -3 and the settings file's -2.
SPREADS = (0.0, math.exp(-5.0), math.exp(-3.5), math.exp(-3.0), math.exp(-2.0))
ENV = "Foosball-FullGame-v0"
ACTIONS = 8  # slide and spin of the four home rods
# The entries the settings file's noise reaches in the second table: rod by rod, slide then
# spin (keeper 0-1, defence 2-3, midfield 4-5, offence 6-7).
GROUPS = (
    ("every entry", range(8)),
    ("the slides", (0, 2, 4, 6)),
    ("the spins", (1, 3, 5, 7)),
    ("keeper and defence", range(4)),
    ("midfield and offence", range(4, 8)),
    ("the slides, midfield and offence spins", (0, 2, 4, 5, 6, 7)),
)


def play(
    options: dict, opponent: str, sd: float, matches: int, entries: range | tuple = range(8)
) -> tuple[int, int]:
    """Goals for and against the action 0 with noise ``sd`` on ``entries`` over ``matches``
    seeded matches."""
    rng = np.random.default_rng(0)
    mask = np.zeros(ACTIONS)
    mask[list(entries)] = 1.0

    def team(obs: np.ndarray) -> np.ndarray:
        return np.clip(rng.normal(0.0, sd, ACTIONS) * mask, -1, 1).astype(np.float32)

    options = {**options, "continuous": True}
    result = evaluate(team, ENV, options, episodes=matches, seed=0, opponent=opponent)
    return result.goals_for, result.goals_against


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--matches", type=int, default=10, help="one-minute matches a condition")
    parser.add_argument("--opponents", nargs="+", default=["scripted:0", "scripted:1"])
    args = parser.parse_args()
    options = read_config_file("builtin:full-game-scratch")["env_kwargs"]
    print(f"builtin:full-game-scratch's options: {options}")
    print(f"{'opponent':<12} {'noise sd':>8} {'for':>5} {'against':>8}")
    for opponent in args.opponents:
        for sd in SPREADS:
            goals_for, goals_against = play(options, opponent, sd, args.matches)
            print(f"{opponent:<12} {sd:>8.3f} {goals_for:>5} {goals_against:>8}")
    sd = SPREADS[-1]
    print(f"\nnoise sd {sd:.3f} on some entries only")
    print(f"{'opponent':<12} {'entries':<40} {'for':>5} {'against':>8}")
    for opponent in args.opponents:
        for name, entries in GROUPS:
            goals_for, goals_against = play(options, opponent, sd, args.matches, entries)
            print(f"{opponent:<12} {name:<40} {goals_for:>5} {goals_against:>8}")


if __name__ == "__main__":
    main()
