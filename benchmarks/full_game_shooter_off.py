"""Does a full-game residual score less because it moves its shooters' aim?

A residual over the attacking team adds its correction to every rod it was given. This plays a
trained full-game residual against the attacking team twice on the same seeded continuous
matches: as trained, and with its correction turned off on the rod that has a ball to shoot
(the attacking team's own shot there, untouched). It prints the goals of each.

    python benchmarks/full_game_shooter_off.py RUN/checkpoints/model_N.zip \
        [--matches 50] [--seed 5000]
"""

from __future__ import annotations

import argparse

import numpy as np

from foosball_gym import load_policy
from foosball_gym.evaluation import evaluate
from foosball_gym.policy_io.task import residual_action

ENV_ID = "Foosball-FullGame-v0"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", help="a residual model trained on Foosball-FullGame-v0")
    parser.add_argument("--matches", type=int, default=50)
    parser.add_argument("--seed", type=int, default=5000)
    args = parser.parse_args()
    loaded = load_policy(args.model)
    if loaded.env_id != ENV_ID or not loaded.trained_residual:
        parser.error(f"{args.model} is not a residual trained on {ENV_ID}")
    loaded = loaded.with_baseline_for(ENV_ID, loaded.env_kwargs)
    team = loaded.baseline

    def shooter_off(obs: np.ndarray) -> np.ndarray:
        correction = np.array(loaded.policy(obs), dtype=np.float64)
        k = team.shooter(obs)
        if k is not None:
            correction[2 * k : 2 * k + 2] = 0.0
        return residual_action(team(obs), loaded.trained_residual, correction)

    print(f"{args.matches} one-minute matches against the attacking team from seed {args.seed}")
    for name, policy in (("as trained", loaded), ("off on the shooter", shooter_off)):
        result = evaluate(
            policy, ENV_ID, loaded.env_kwargs, args.matches, seed=args.seed, opponent="scripted"
        )
        print(f"{name:20s} goals for {result.goals_for:4d}  against {result.goals_against:4d}")


if __name__ == "__main__":
    main()
