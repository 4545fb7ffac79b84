"""Do the two cores slow each other? Environments stepped by processes that share nothing.

Each process steps its own N environments of an id in a loop with random actions (resets
included), alone and then beside a twin started at the same time; nothing passes between
them. If a process steps as fast beside its twin as alone, the cores and their caches are not
what slows a vec env split over two processes: its messages and waits are.

    python benchmarks/independent_envs.py [--env Foosball-Block-v0] [--envs 1 8] [--steps 40000]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import time
from typing import Any

import numpy as np


def step_envs(env_id: str, n_envs: int, steps: int, out: Any) -> None:
    import gymnasium as gym

    import foosball_gym  # noqa: F401  (registers the environments)

    envs = [gym.make(env_id) for _ in range(n_envs)]
    for i, env in enumerate(envs):
        env.reset(seed=i)
    shape = (steps // n_envs, n_envs, *envs[0].action_space.shape)
    actions = np.random.default_rng(0).uniform(-1, 1, shape).astype(np.float32)
    start = time.perf_counter()
    for row in actions:
        for env, action in zip(envs, row, strict=True):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
    out.put(actions.shape[0] * n_envs / (time.perf_counter() - start))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Foosball-Block-v0")
    parser.add_argument("--envs", type=int, nargs="+", default=[1, 8])
    parser.add_argument("--steps", type=int, default=40_000, help="steps per process")
    args = parser.parse_args()
    ctx = mp.get_context("spawn")
    print(f"{args.env}, {args.steps:,} steps a process, env steps/s")
    for n_envs in args.envs:
        for procs in (1, 2):
            out = ctx.Queue()
            workers = [
                ctx.Process(target=step_envs, args=(args.env, n_envs, args.steps, out))
                for _ in range(procs)
            ]
            for w in workers:
                w.start()
            rates = [out.get() for _ in workers]
            for w in workers:
                w.join()
            each = ", ".join(f"{r:,.0f}" for r in rates)
            print(f"{n_envs} environments a process, {procs} process(es): {each}")


if __name__ == "__main__":
    main()
