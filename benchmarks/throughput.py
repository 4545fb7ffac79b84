"""Env steps per second of every registered environment, single process, random actions.

Resets are included; the opponent of two-player envs (the default scripted one) is included.
Physics steps per second count every physics step the simulator took (finer near contacts).

    python benchmarks/throughput.py [--steps N] [--env ID ...]
"""

from __future__ import annotations

import argparse
import os
import time

import gymnasium as gym
import numpy as np

import foosball_gym


def measure(env_id: str, steps: int, seed: int = 0, **kwargs) -> tuple[float, float, int]:
    env = gym.make(env_id, **kwargs)
    rng = np.random.default_rng(seed)
    # Drawn up front: Box.sample() costs more than a Block step and is not the env's cost.
    actions = rng.uniform(-1, 1, (steps, *env.action_space.shape)).astype(np.float32)
    env.reset(seed=seed)
    resets = 0
    start = time.perf_counter()
    for a in actions:
        _, _, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
            resets += 1
    elapsed = time.perf_counter() - start
    physics_per_step = env.unwrapped.sim.physics_steps / steps
    env.close()
    rate = steps / elapsed
    return rate, rate * physics_per_step, resets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="env steps per environment")
    parser.add_argument(
        "--env",
        nargs="*",
        default=list(foosball_gym.ENV_IDS),
        help="environment ids (default: all registered)",
    )
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    print(f"{'environment':32s} {'env steps/s':>12s} {'physics steps/s':>16s} {'resets':>7s}")
    for env_id in args.env:
        measure(env_id, min(args.steps, 500))  # warm-up: imports, URDF cache
        rate, physics, resets = measure(env_id, args.steps)
        print(f"{env_id:32s} {rate:12,.0f} {physics:16,.0f} {resets:7d}")


if __name__ == "__main__":
    main()
