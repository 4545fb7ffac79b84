"""What a copy of an environment costs: pickling it, unpickling it (which builds the copy's
Bullet worlds), deep-copying it, and the pickle's size, per registered environment, against
making a new environment with gym.make.

Each env is copied in the middle of play (reset and 50 random steps). Single process, one
core; the median of ``--repeats``.

    python benchmarks/copies.py [--env ID ...] [--repeats N]
"""

from __future__ import annotations

import argparse
import copy
import os
import pickle
import statistics
import time

import gymnasium as gym
import numpy as np

import foosball_gym


def timed(fn, repeats: int) -> float:
    """The median time of ``fn()`` in milliseconds; what it returns is closed where it can be."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        made = fn()
        times.append(time.perf_counter() - start)
        if hasattr(made, "close"):
            made.close()
    return 1e3 * statistics.median(times)


def measure(env_id: str, repeats: int) -> dict[str, float]:
    env = gym.make(env_id)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for action in rng.uniform(-1, 1, (50, *env.action_space.shape)).astype(np.float32):
        env.step(action)
    data = pickle.dumps(env)
    result = {
        "make": timed(lambda: gym.make(env_id), repeats),
        "dumps": timed(lambda: pickle.dumps(env), repeats),
        "loads": timed(lambda: pickle.loads(data), repeats),
        "deepcopy": timed(lambda: copy.deepcopy(env), repeats),
        "kB": len(data) / 1e3,
    }
    env.close()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", nargs="*", default=list(foosball_gym.ENV_IDS))
    parser.add_argument("--repeats", type=int, default=15, help="copies timed per figure (15)")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    measure(args.env[0], 2)  # warm-up: imports, the URDFs written once per process
    print(
        f"{'environment':30s} {'make ms':>8s} {'dumps ms':>9s} {'loads ms':>9s}"
        f" {'deepcopy ms':>12s} {'pickle kB':>10s}"
    )
    for env_id in args.env:
        r = measure(env_id, args.repeats)
        print(
            f"{env_id:30s} {r['make']:8.1f} {r['dumps']:9.2f} {r['loads']:9.1f}"
            f" {r['deepcopy']:12.1f} {r['kB']:10.1f}"
        )


if __name__ == "__main__":
    main()
