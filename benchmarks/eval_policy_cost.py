"""What a run's evaluations cost with the policy in PyTorch (SB3's predict) and in NumPy.

A run evaluates every ``eval_freq`` steps on ``eval_episodes`` episodes, one environment and
one observation at a time. This builds a recipe's PPO model, untrained, and times one action
from each snapshot of it, then whole evaluations with each, side by side.

    OMP_NUM_THREADS=1 python benchmarks/eval_policy_cost.py [--config builtin:block-scratch]
                                                           [--calls 5000] [--episodes 50]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="builtin:block-scratch")
    parser.add_argument("--calls", type=int, default=5_000)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--rounds", type=int, default=2)
    args = parser.parse_args()

    from foosball_gym.evaluation import evaluate
    from foosball_gym.training.config_file import load_train_config
    from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot
    from foosball_gym.training.sb3.model import build_model
    from foosball_gym.training.sb3.numpy_snapshot import NumpySnapshot
    from foosball_gym.training.sb3.vec_env import make_env

    config = load_train_config(
        args.config, overrides={"n_envs": 1, "vec_env": "dummy", "batch_size": 64}
    )
    config.check()
    venv = make_env(config)
    model = build_model(config, venv, None)
    snapshots = {
        "PyTorch (predict)": PolicySnapshot.of_model(model),
        "NumPy": NumpySnapshot.of_model(model),
    }
    obs = np.random.default_rng(0).normal(size=snapshots["NumPy"].observation_size)
    print(f"{config.env_id}, {args.config}: µs an action, s an evaluation of {args.episodes}")
    for _ in range(args.rounds):
        for name, snapshot in snapshots.items():
            start = time.perf_counter()
            for _ in range(args.calls):
                snapshot(obs)
            action = (time.perf_counter() - start) / args.calls * 1e6
            start = time.perf_counter()
            evaluate(snapshot, config.env_id, config.env_kwargs, episodes=args.episodes, seed=0)
            episodes = time.perf_counter() - start
            print(f"  {name:>18}  {action:7.1f} µs  {episodes:6.2f} s")
    venv.close()


if __name__ == "__main__":
    main()
