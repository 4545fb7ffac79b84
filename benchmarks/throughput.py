"""Env steps per second of every registered environment, single process, with random actions
and with the task's scripted policy playing.

Resets are included; the opponent of two-player envs (the default scripted one) is included.
Physics steps per env step count every physics step the simulator took (finer near contacts):
random actions swing rods at full speed beside the ball, scripted play keeps the ball at the
figurines' feet.

    python benchmarks/throughput.py [--steps N] [--env ID ...] [--play random|scripted ...]
                                    [--against DIR [--rounds R]]

``--against DIR`` measures the package in another checkout too (e.g. a ``git worktree`` of the
commit before a change), alternating the two in fresh processes round by round, and prints the
median of each and their ratio: a before/after comparison taken in one run on one machine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np

import foosball_gym

PLAYS = ("random", "scripted")


def measure(
    env_id: str, steps: int, seed: int = 0, play: str = "random", **kwargs
) -> tuple[float, float, int]:
    """Env steps/s, physics steps per env step and resets of ``steps`` steps of ``play``."""
    if play not in PLAYS:
        raise ValueError(f"play must be one of {', '.join(PLAYS)}, got {play!r}")
    env = gym.make(env_id, **kwargs)
    rng = np.random.default_rng(seed)
    # Drawn up front: Box.sample() costs more than a Block step and is not the env's cost.
    actions = rng.uniform(-1, 1, (steps, *env.action_space.shape)).astype(np.float32)
    policy = env.unwrapped.scripted_policy() if play == "scripted" else None
    obs, _ = env.reset(seed=seed)
    before = env.unwrapped.sim.physics_steps
    resets = 0
    start = time.perf_counter()
    for a in actions:
        obs, _, terminated, truncated, _ = env.step(a if policy is None else policy(obs))
        if terminated or truncated:
            obs, _ = env.reset()
            resets += 1
    elapsed = time.perf_counter() - start
    physics_per_step = (env.unwrapped.sim.physics_steps - before) / steps
    env.close()
    return steps / elapsed, physics_per_step, resets


def _measure_in(checkout: str, env_id: str, steps: int, play: str) -> float:
    """Env steps/s of ``env_id`` with the package of ``checkout``, in a fresh process."""
    code = (
        "import json, sys; sys.path.insert(0, sys.argv[1]); sys.path.insert(1, sys.argv[2]);"
        "import throughput; throughput.measure(sys.argv[3], 500, play=sys.argv[5]);"
        "print(json.dumps(throughput.measure(sys.argv[3], int(sys.argv[4]), play=sys.argv[5])[0]))"
    )
    here = os.path.dirname(os.path.abspath(__file__))
    out = subprocess.run(
        [sys.executable, "-c", code, checkout, here, env_id, str(steps), play],
        capture_output=True,
        text=True,
        check=True,
    )
    return float(json.loads(out.stdout.strip().splitlines()[-1]))


def compare(against: str, envs: list[str], steps: int, rounds: int, plays: list[str]) -> None:
    this = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    print(f"this: {this}\nagainst: {os.path.abspath(against)}")
    print(
        f"{'environment':32s} {'play':>9s} {'against /s':>11s} {'this /s':>11s}"
        f" {'this/against':>13s}"
    )
    for env_id in envs:
        for play in plays:
            rates: dict[str, list[float]] = {"against": [], "this": []}
            for r in range(rounds):
                order = [("against", against), ("this", this)]
                for name, checkout in order if r % 2 == 0 else order[::-1]:
                    rates[name].append(_measure_in(checkout, env_id, steps, play))
            a, t = statistics.median(rates["against"]), statistics.median(rates["this"])
            print(f"{env_id:32s} {play:>9s} {a:11,.0f} {t:11,.0f} {t / a:13.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20000, help="env steps per environment")
    parser.add_argument(
        "--env",
        nargs="*",
        default=list(foosball_gym.ENV_IDS),
        help="environment ids (default: all registered)",
    )
    parser.add_argument(
        "--play", nargs="*", choices=PLAYS, default=list(PLAYS), help="what plays (both)"
    )
    parser.add_argument("--against", metavar="DIR", help="another checkout to compare with")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of --against (3)")
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    if args.against:
        compare(args.against, args.env, args.steps, args.rounds, args.play)
        return
    print(
        f"{'environment':32s} {'play':>9s} {'env steps/s':>12s} {'physics/step':>13s}"
        f" {'resets':>7s}"
    )
    for env_id in args.env:
        for play in args.play:
            measure(env_id, min(args.steps, 500), play=play)  # warm-up: imports, URDF cache
            rate, physics, resets = measure(env_id, args.steps, play=play)
            print(f"{env_id:32s} {play:>9s} {rate:12,.0f} {physics:13.1f} {resets:7d}")


if __name__ == "__main__":
    main()
