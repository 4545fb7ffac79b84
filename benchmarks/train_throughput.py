"""Env steps per second of ``foosball train``, stage by stage, as Isaac Lab's tables give them:

- ``env``: the run's vectorised environments (its vec_env, n_envs, normalisation and self-play
  wrappers) stepped with random actions;
- ``+ inference``: SB3's rollouts, the policy choosing every action, no learning;
- ``+ training``: the whole run, from the first rollout to the last update, checkpoints
  included (building the run and its evaluations are not timed: a full game's evaluation is
  50 matches of a minute each, more steps than 180,000 of training).

Beside them, ``1 env, 1 process`` is one environment stepped alone with random actions, and
``x cores`` that figure times the cores this process may use: what the environments alone
could give if nothing else ran. The training row's share of it is the learner's efficiency;
its share of one environment alone is the yardstick the learner's target was first measured by
("today about 8 %": 1,700 env steps/s of training against 22,000 of one environment).

    python benchmarks/train_throughput.py [--env ID] [--config FILE|builtin:ID]
                                          [--steps N] [--set KEY=VALUE ...] [--against DIR]

``--config`` takes what ``foosball train --config`` takes (default: the env's defaults, as
``foosball train ENV_ID`` runs); ``--set`` overrides a field (``--set vec_env=dummy``).
``--against DIR`` measures the package of another checkout too (e.g. a ``git worktree`` of the
commit before a change), in fresh processes, alternating with this one.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np

STAGES = ("env", "+ inference", "+ training")


def _config(env_id: str, config_file: str | None, overrides: dict[str, Any], steps: int) -> Any:
    from foosball_gym.training.config import TrainConfig

    if config_file:
        try:
            from foosball_gym.training.config_file import load_train_config
        except ImportError:  # a checkout from before settings files
            raise SystemExit("--config needs a checkout with settings files") from None
        config = load_train_config(config_file, env_id, {})
    else:
        config = TrainConfig(env_id)
    import yaml

    for key, value in overrides.items():
        # Read as a settings file reads it: false, null, 1e-4 and [64, 64] mean what they say.
        setattr(config, key, yaml.safe_load(value))
    config.timesteps = steps
    config.eval_freq = steps + 1
    config.eval_episodes = 1  # the one evaluation at the end, which is not timed
    config.pretrain_episodes = 0
    config.check()
    return config


def env_alone(env_id: str, steps: int) -> float:
    """Env steps/s of one environment in this process, random actions, resets included."""
    import gymnasium as gym

    import foosball_gym  # noqa: F401

    env = gym.make(env_id)
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, *env.action_space.shape))
    actions = actions.astype(np.float32)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


def measure(stage: str, config: Any) -> float:
    """Env steps/s of ``stage`` (one of :data:`STAGES`) for ``config.timesteps`` steps."""
    import torch as th

    from foosball_gym.training.sb3.vec_env import make_env

    th.set_num_threads(config.torch_threads)
    if stage == "+ training":
        return _training(config)
    venv = make_env(config)
    try:
        if stage == "env":
            venv.reset()
            n = venv.num_envs
            rounds = max(config.timesteps // n, 1)
            rng = np.random.default_rng(0)
            shape = (rounds, n, *venv.action_space.shape)
            actions = rng.uniform(-1, 1, shape).astype(np.float32)
            start = time.perf_counter()
            for action in actions:
                venv.step(action)
            return rounds * n / (time.perf_counter() - start)
        from foosball_gym.training.sb3.model import build_model

        model = build_model(config, venv, None)
        _, callback = model._setup_learn(config.timesteps, None)
        start, done = time.perf_counter(), 0
        while done < config.timesteps:
            model.collect_rollouts(venv, callback, model.rollout_buffer, model.n_steps)
            done += model.n_steps * venv.num_envs
        return done / (time.perf_counter() - start)
    finally:
        venv.close()


def _training(config: Any) -> float:
    from stable_baselines3.common.callbacks import BaseCallback

    try:
        from foosball_gym.training.sb3.trainer import train
    except ImportError:  # a checkout from before training/ was split by job
        from foosball_gym.training.run import train  # type: ignore[no-redef]

    class Clock(BaseCallback):
        def _on_training_start(self) -> None:
            self.start, self.steps = time.perf_counter(), self.model.num_timesteps

        def _on_step(self) -> bool:
            return True

        def _on_training_end(self) -> None:
            self.rate = (self.model.num_timesteps - self.steps) / (time.perf_counter() - self.start)

    clock = Clock()
    with tempfile.TemporaryDirectory() as out:
        train(config, out, callbacks=[clock])
    return clock.rate


def _measure_in(checkout: str, what: str, args: argparse.Namespace) -> float:
    """``what`` (a stage, or "alone") measured in a fresh process on ``checkout``'s package."""
    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); sys.path.insert(1, sys.argv[2]);"
        "import train_throughput as t; a = json.loads(sys.argv[3]);"
        "r = t.env_alone(a['env'], a['steps']) if a['what'] == 'alone' else "
        "t.measure(a['what'], t._config(a['env'], a['config'], a['set'], a['steps']));"
        "print(json.dumps(r))"
    )
    here = os.path.dirname(os.path.abspath(__file__))
    spec = {
        "what": what,
        "env": args.env,
        "config": args.config,
        "set": dict(args.set),
        "steps": args.steps if what != "alone" else min(args.steps, 20_000),
    }
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, "-c", code, checkout, here, json.dumps(spec)],
        capture_output=True,
        text=True,
        env=env,
    )
    if out.returncode:
        raise SystemExit(f"{checkout}: {what} failed:\n{out.stderr[-3000:]}")
    return float(json.loads(out.stdout.strip().splitlines()[-1]))


def _key_value(text: str) -> tuple[str, str]:
    key, sep, value = text.partition("=")
    if not sep:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    return key, value


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="Foosball-Block-v0", help="environment id")
    parser.add_argument("--config", help="a settings file, as foosball train --config takes")
    parser.add_argument("--steps", type=int, default=65536, help="env steps per measurement")
    parser.add_argument("--set", type=_key_value, action="append", default=[], metavar="K=V")
    parser.add_argument("--against", metavar="DIR", help="another checkout to compare with")
    args = parser.parse_args()
    this = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    checkouts = [("this", this)] + ([("against", args.against)] if args.against else [])
    cores = _cores()
    print(f"{args.env}, {args.config or 'the defaults'}, {args.steps} steps, {cores} cores")
    header = f"{'checkout':>9s} {'stage':>18s} {'env steps/s':>12s}"
    print(f"{header} {'of x cores':>11s} {'of 1 env':>9s}")
    alone = {name: _measure_in(checkout, "alone", args) for name, checkout in checkouts[::-1]}
    for name, _ in checkouts[::-1]:
        print(f"{name:>9s} {'1 env, 1 process':>18s} {alone[name]:12,.0f} {'':>11s} {'100 %':>9s}")
        print(f"{name:>9s} {f'x {cores} cores':>18s} {alone[name] * cores:12,.0f} {'100 %':>11s}")
    for stage in STAGES:
        for name, checkout in checkouts[::-1]:
            rate = _measure_in(checkout, stage, args)
            share = f"{100 * rate / (alone[name] * cores):.0f} %"
            of_one = f"{100 * rate / alone[name]:.0f} %"
            print(f"{name:>9s} {stage:>18s} {rate:12,.0f} {share:>11s} {of_one:>9s}", flush=True)


if __name__ == "__main__":
    main()
