"""Self-play throughput: env steps per second of KeeperVsKeeper training with the learned
(self-play) opponent and with the scripted opponent, and the cost of opponent inference.

    python benchmarks/selfplay_throughput.py [--timesteps N] [--n-envs N]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
import torch as th

from foosball_gym.training.config import TrainConfig
from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot
from foosball_gym.training.sb3.model import build_model
from foosball_gym.training.sb3.vec_env import make_env
from foosball_gym.training.selfplay.callback import SelfPlayCallback
from foosball_gym.training.selfplay.opponents import find_selfplay_env

ENV = "Foosball-KeeperVsKeeper-v0"


def run(self_play: bool, timesteps: int, n_envs: int) -> tuple[float, float]:
    config = TrainConfig(ENV, n_envs=n_envs, self_play=self_play, timesteps=timesteps)
    config.check()
    venv = make_env(config)
    model = build_model(config, venv, None)
    callback = SelfPlayCallback(threshold=0.2) if self_play else None
    start = time.perf_counter()
    model.learn(timesteps, callback=callback)
    elapsed = time.perf_counter() - start
    opponent = find_selfplay_env(venv).opponent_seconds if self_play else 0.0
    # With worker_rollouts each process chooses its own environments' opponents, side by side.
    processes = len(getattr(find_selfplay_env(venv).venv, "shares", [0])) if self_play else 1
    processes = processes if config.worker_rollouts else 1
    venv.close()
    return model.num_timesteps / elapsed, opponent / (elapsed * processes)


def batched_vs_single(n_envs: int, repeats: int = 2000) -> tuple[float, float]:
    config = TrainConfig(ENV, n_envs=1, self_play=True)
    config.check()
    venv = make_env(config)
    snap = PolicySnapshot.of_model(build_model(config, venv, None))
    venv.close()
    obs = np.random.default_rng(0).normal(size=(n_envs, 10)).astype(np.float32)
    start = time.perf_counter()
    for _ in range(repeats):
        snap(obs)
    batched = (time.perf_counter() - start) / repeats
    start = time.perf_counter()
    for _ in range(repeats):
        for row in obs:
            snap(row)
    single = (time.perf_counter() - start) / repeats
    return batched, single


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--timesteps", type=int, default=40_000)
    parser.add_argument("--n-envs", type=int, default=8)
    args = parser.parse_args()
    th.set_num_threads(1)
    with tempfile.TemporaryDirectory():
        for label, self_play in (("scripted opponent", False), ("self-play opponent", True)):
            rate, share = run(self_play, args.timesteps, args.n_envs)
            extra = ""
            if self_play:
                extra = f", opponent inference {100 * share:.1f} % of the processes' time"
            print(f"{ENV} training, {label:18s}: {rate:7,.0f} env steps/s{extra}")
    batched, single = batched_vs_single(args.n_envs)
    print(
        f"opponent inference for {args.n_envs} envs: one batched call {1e6 * batched:.0f} us, "
        f"{args.n_envs} single calls {1e6 * single:.0f} us per step"
    )


if __name__ == "__main__":
    main()
