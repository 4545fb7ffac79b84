"""How self-play sampling scales: env steps per second of KeeperVsKeeper self-play sampled
by 1, 2, ... Ray RLlib env runners (learning not included), beside the SB3 backend's sampling
in one process in the same run.

    python benchmarks/scaling.py [--workers 1 2] [--steps N] [--n-envs N]

Each env runner takes one CPU; the figures only scale while there are cores to give them.
"""

from __future__ import annotations

import argparse
import time

import ray
from ray.tune.registry import register_env

from foosball_gym.training.config import TrainConfig
from foosball_gym.training.rllib.env_runner import ENV_NAME, make_game, opponent_id
from foosball_gym.training.rllib.ray_config import build_config

ENV = "Foosball-KeeperVsKeeper-v0"


def steps_per_second(workers: int, steps: int, envs_per_runner: int, repeats: int) -> float:
    # The same work per runner at every count: more runners, more envs in all.
    n_envs = envs_per_runner * workers
    config = TrainConfig(ENV, n_envs=n_envs, net_arch=(256, 128, 64), batch_size=128 * n_envs)
    config.check()
    ray.init(address="local", num_cpus=workers, include_dashboard=False, log_to_driver=False)
    try:
        register_env(ENV_NAME, make_game)
        algo = build_config(config, workers, (opponent_id(0),), 1e-3, steps).build_algo()
        group = algo.env_runner_group
        per_runner = steps // workers

        def sample(runner):
            return sum(len(e) for e in runner.sample(num_timesteps=per_runner))

        group.foreach_env_runner(sample, local_env_runner=False)  # warm-up: envs built, reset
        rates = []
        for _ in range(repeats):
            start = time.perf_counter()
            done = sum(group.foreach_env_runner(sample, local_env_runner=False))
            rates.append(done / (time.perf_counter() - start))
        algo.stop()
    finally:
        ray.shutdown()
    return max(rates)


def sb3_steps_per_second(steps: int, n_envs: int) -> float:
    """The SB3 backend's sampling: its self-play VecEnv stepped with the learner's policy (the
    opponents' batched inference included), in this process."""
    from foosball_gym.training.sb3.model import build_model
    from foosball_gym.training.sb3.vec_env import make_env

    config = TrainConfig(ENV, n_envs=n_envs, net_arch=(256, 128, 64), self_play=True)
    config.check()
    venv = make_env(config)
    model = build_model(config, venv, None)
    obs = venv.reset()
    for _ in range(20):  # warm-up
        obs, *_ = venv.step(model.predict(obs)[0])
    start = time.perf_counter()
    for _ in range(steps // n_envs):
        obs, *_ = venv.step(model.predict(obs)[0])
    rate = (steps // n_envs) * n_envs / (time.perf_counter() - start)
    venv.close()
    return rate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--steps", type=int, default=8000, help="env steps per measurement")
    parser.add_argument("--n-envs", type=int, default=1, help="envs per env runner (1)")
    parser.add_argument("--repeats", type=int, default=3, help="measurements; the best is shown")
    args = parser.parse_args()
    sb3 = sb3_steps_per_second(args.steps, 8)
    print(f"SB3, one process (8 envs, the CLI default): {sb3:8.0f} env steps/s")
    base = None
    for workers in args.workers:
        rate = steps_per_second(workers, args.steps * workers, args.n_envs, args.repeats)
        base = base or rate
        print(f"{workers} env runner(s): {rate:8.0f} env steps/s  ({rate / base:.2f}x)")


if __name__ == "__main__":
    main()
