"""What an environment step costs with a policy playing, against random actions.

The environments' speed is usually measured with random actions (``throughput.py``,
``train_throughput.py``'s ``1 env`` row), but a keeper that meets the ball makes the simulator
step finely near contacts, so training, which plays its policy, steps a costlier environment.
This steps one environment in this process, alternately with random actions and with a
policy's own choices, and times the environment alone (the policy's time is left out).

    python benchmarks/policy_cost.py [--env Foosball-Block-v0] [--policy builtin:block]
                                     [--steps 10000] [--rounds 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def env_cost(env_id: str, policy: object, steps: int) -> tuple[float, float]:
    """(µs a step in the environment, µs a step choosing) over ``steps`` steps; ``policy`` None
    draws random actions."""
    import gymnasium as gym

    import foosball_gym  # noqa: F401  (registers the environments)

    env = gym.make(env_id)
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    choosing = stepping = 0.0
    for _ in range(steps):
        start = time.perf_counter()
        if policy is None:
            action = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        else:
            action = policy(obs)  # type: ignore[operator]
        middle = time.perf_counter()
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()
        stepping += time.perf_counter() - middle
        choosing += middle - start
    env.close()
    return stepping / steps * 1e6, choosing / steps * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Foosball-Block-v0")
    parser.add_argument("--policy", default="builtin:block", help="a run, a .zip or builtin:NAME")
    parser.add_argument("--steps", type=int, default=10_000)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()
    from foosball_gym.training.loading import load_policy

    policy = load_policy(args.policy)
    print(f"{args.env}, {args.steps:,} steps each, µs a step in the environment")
    for _ in range(args.rounds):
        for name, chooser in (("random actions", None), (args.policy, policy)):
            cost, _ = env_cost(args.env, chooser, args.steps)
            print(f"  {name:>24}  {cost:6.1f}")


if __name__ == "__main__":
    main()
