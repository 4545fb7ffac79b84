"""Env steps per second of ``foosball train``: the run's own configuration (PPO and every
default but the length) for an environment, its environments in this process (``dummy``) or
one process each (``subproc``). Timed from the first rollout to the last update: learning and
checkpoints included, as a run has them; building the run and evaluating it are not (a full
game's evaluation is 50 matches of a minute each: more steps than 180,000 of training).

    python benchmarks/train_throughput.py [--env ID] [--steps N] [--n-envs N]
                                          [--vec-env dummy subproc] [--against DIR]

``--against DIR`` trains with the package of another checkout too (e.g. a ``git worktree`` of
the commit before a change), in fresh processes, alternating with this one.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

VEC_ENVS = ("dummy", "subproc")


def measure(env_id: str, steps: int, n_envs: int, vec_env: str) -> float:
    """Env steps/s of training ``env_id`` for ``steps`` steps."""
    from stable_baselines3.common.callbacks import BaseCallback

    from foosball_gym.training.config import TrainConfig

    try:
        from foosball_gym.training.sb3.trainer import train
    except ImportError:  # a checkout from before training/ was split by job
        from foosball_gym.training.run import train

    class Clock(BaseCallback):
        def _on_training_start(self) -> None:
            self.start, self.steps = time.perf_counter(), self.model.num_timesteps

        def _on_step(self) -> bool:
            return True

        def _on_training_end(self) -> None:
            self.rate = (self.model.num_timesteps - self.steps) / (time.perf_counter() - self.start)

    config = TrainConfig(
        env_id, timesteps=steps, n_envs=n_envs, vec_env=vec_env, eval_freq=steps + 1
    )
    config.eval_episodes = 1  # the one evaluation at the end, which is not timed
    clock = Clock()
    with tempfile.TemporaryDirectory() as out:
        train(config, out, callbacks=[clock])
    return clock.rate


def _measure_in(checkout: str, env_id: str, steps: int, n_envs: int, vec_env: str) -> float:
    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); sys.path.insert(1, sys.argv[2]);"
        "import train_throughput as t;"
        "print(json.dumps(t.measure(sys.argv[3], int(sys.argv[4]), int(sys.argv[5]), sys.argv[6])))"
    )
    here = os.path.dirname(os.path.abspath(__file__))
    args = [checkout, here, env_id, str(steps), str(n_envs), vec_env]
    out = subprocess.run(
        [sys.executable, "-c", code, *args], capture_output=True, text=True, check=True
    )
    return float(json.loads(out.stdout.strip().splitlines()[-1]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Foosball-FullGame-v0", help="environment id")
    parser.add_argument("--steps", type=int, default=65536, help="env steps per run")
    parser.add_argument("--n-envs", type=int, default=8, help="environments (8, the default)")
    parser.add_argument("--vec-env", nargs="*", choices=VEC_ENVS, default=list(VEC_ENVS))
    parser.add_argument("--against", metavar="DIR", help="another checkout to compare with")
    args = parser.parse_args()
    this = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    checkouts = [("this", this)] + ([("against", args.against)] if args.against else [])
    print(f"{args.env}, {args.steps} steps, {args.n_envs} environments, {os.cpu_count()} CPUs")
    print(f"{'checkout':>9s} {'vec_env':>8s} {'env steps/s':>12s}")
    for vec_env in args.vec_env:
        for name, checkout in checkouts[::-1]:
            rate = _measure_in(checkout, args.env, args.steps, args.n_envs, vec_env)
            print(f"{name:>9s} {vec_env:>8s} {rate:12,.0f}")


if __name__ == "__main__":
    main()
