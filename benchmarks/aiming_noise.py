"""How much exploration noise an aimed shot past standing figurines survives, and a straight one.

The scripted aiming keeper of Score with obstacles (``Foosball-Score-v0``, ball at rest,
``obstacles=True``), and the same keeper kicking straight only, play the seeded balls
``seed .. seed + episodes - 1`` with Gaussian noise added to their actions at every step, as a
PPO learner's exploring policy adds it to its mean: on both entries, on the slide alone and on
the spin alone. The noise is in the action's own units, each entry in [-1, 1]: a slide of 1 is
12.3 cm of the rod's travel, a spin of 1 is 2 pi of its turn. It prints the success of each
condition with its Wilson interval, and the goals for and against.

    python benchmarks/aiming_noise.py [--episodes 200] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
from typing import Any, cast

import gymnasium as gym
import numpy as np

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.evaluation import evaluate, wilson_interval
from foosball_gym.policies.scripted import ScriptedTeam

ENV = "Foosball-Score-v0"
OPTIONS: dict[str, Any] = {"ball_start": "resting", "obstacles": True}
# Standard deviations in the action's units: none, then from 0.4 mm of slide to exp(-1), the
# starting spread of builtin:score-obstacles-scratch.
SPREADS = (0.0, 0.003, 0.01, 0.03, 0.1, math.exp(-1.0))
ENTRIES = (("both", (0, 1)), ("slide", (0,)), ("spin", (1,)))
KEEPERS = ("aiming", "straight")


def play(
    keeper_name: str, sd: float, entries: tuple[int, ...], episodes: int, seed: int
) -> tuple[int, int, int]:
    """Balls scored, goals for and against by the ``aiming`` or ``straight`` keeper with noise
    ``sd`` on ``entries`` of its action."""
    env = gym.make(ENV, **OPTIONS)
    keeper = cast(FoosballEnv, env.unwrapped).scripted_policy()
    if keeper_name == "straight":
        names = cast(FoosballEnv, env.unwrapped).obs_builder.names
        keeper = ScriptedTeam(names, ("home_keeper",), "both", volley=True, aim=False)
    env.close()
    rng = np.random.default_rng(seed)
    mask = np.zeros(2)
    mask[list(entries)] = 1.0

    def noisy(obs: np.ndarray) -> np.ndarray:
        action = np.asarray(keeper(obs), np.float64) + rng.normal(0.0, sd, 2) * mask
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    result = evaluate(noisy, ENV, OPTIONS, episodes=episodes, seed=seed)
    scored = round(result.success_rate * episodes)
    return scored, result.goals_for, result.goals_against


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=200, help="seeded balls a condition")
    parser.add_argument("--seed", type=int, default=0, help="the first ball's seed")
    args = parser.parse_args()
    print(f"{ENV} {OPTIONS}, balls {args.seed}-{args.seed + args.episodes - 1}")
    header = ("keeper", "noise on", "sd", "success", "95 % interval", "for", "against")
    print("{:<8} {:<8} {:>6} {:>8} {:>14} {:>5} {:>8}".format(*header))
    for keeper in KEEPERS:
        for name, entries in ENTRIES:
            for sd in SPREADS:
                if sd == 0.0 and name != "both":
                    continue  # no noise is one condition, shown once
                scored, goals_for, goals_against = play(
                    keeper, sd, entries, args.episodes, args.seed
                )
                low, high = wilson_interval(scored, args.episodes)
                interval = f"{100 * low:.1f}-{100 * high:.1f} %"
                print(
                    f"{keeper:<8} {name:<8} {sd:>6.3f} {100 * scored / args.episodes:>7.1f}% "
                    f"{interval:>14} {goals_for:>5} {goals_against:>8}"
                )


if __name__ == "__main__":
    main()
