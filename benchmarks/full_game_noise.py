"""How much exploration noise costs the attacking team in the full game.

A residual learner over the attacking team (``residual``) explores by adding Gaussian noise to
its actions. This plays the attacking team with such noise on some of its rods against the
attacking team without it, in continuous one-minute matches, and prints the goals of each
condition: what a learner's exploring matches look like before it has learned anything.

    python benchmarks/full_game_noise.py [--matches 10]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np

import foosball_gym  # noqa: F401  (registers the environments)

# The action is rod by rod, slide then spin: keeper 0-1, defence 2-3, midfield 4-5, offence 6-7.
CONDITIONS = [
    ("no noise", (), 0.0),
    ("every rod, sd 0.03", range(8), 0.03),
    ("every rod, sd 0.07", range(8), 0.07),
    ("keeper and defence, sd 0.1", range(4), 0.1),
    ("midfield and offence, sd 0.1", range(4, 8), 0.1),
    ("every slide, sd 0.07", (0, 2, 4, 6), 0.07),
    ("every spin, sd 0.07", (1, 3, 5, 7), 0.07),
]


def play(dims: tuple[int, ...] | range, sd: float, matches: int) -> tuple[int, int]:
    """Goals for and against the noisy attacking team over ``matches`` seeded matches."""
    env = gym.make("Foosball-FullGame-v0", continuous=True)
    team = env.unwrapped.scripted_policy()
    mask = np.zeros(env.action_space.shape[0])
    mask[list(dims)] = sd
    rng = np.random.default_rng(0)
    goals_for = goals_against = 0
    for seed in range(matches):
        obs, _ = env.reset(seed=seed)
        done = False
        info: dict = {}
        while not done:
            noise = mask * rng.standard_normal(mask.shape)
            action = np.clip(np.asarray(team(obs)) + noise, -1.0, 1.0)
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        goals_for += info["goals_for"]
        goals_against += info["goals_against"]
    env.close()
    return goals_for, goals_against


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--matches", type=int, default=10)
    args = parser.parse_args()
    print(f"the attacking team with noise against itself, {args.matches} one-minute matches")
    print(f"{'noise':32s} {'for':>5s} {'against':>8s} {'s':>6s}")
    for name, dims, sd in CONDITIONS:
        start = time.perf_counter()
        goals_for, goals_against = play(dims, sd, args.matches)
        print(f"{name:32s} {goals_for:5d} {goals_against:8d} {time.perf_counter() - start:6.0f}")


if __name__ == "__main__":
    main()
