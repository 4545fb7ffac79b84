"""Which aims score, ball by ball, where a figurine shuts the straight lane.

    python scripts/aim_windows.py RUN [--episodes 40] [--seed 0] [--points 201]

``RUN`` is a policy trained on ``Foosball-Score-v0`` with obstacles whose slide is read around
the ball (``slide_around_ball``, with or without ``slide_skip``), what ``foosball eval`` takes.
On each of the seeded balls ``seed .. seed + episodes - 1`` whose straight lane is shut (the
aiming keeper's clearance test, as ``scripts/shot_lanes.py`` judges it), the policy plays with
its slide action held at each of ``--points`` values evenly spaced over [-1, 1], its spin as it
chooses, so that it strikes with the figurine at a fixed place beside the ball. For each ball
it prints how many of the held values score, in how many windows (runs of neighbouring values
that all score), the widest window's width in the action's units, how many of the values
within 0.1 of 0 (the straight kick) score, and a strip of the values, ``#`` where one scores;
then the same over all the shut balls.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import foosball_gym

ENV_ID = "Foosball-Score-v0"
STRAIGHT = 0.1  # held slide values this near 0 kick straight


def windows(hits: Sequence[bool]) -> list[int]:
    """The lengths of the runs of neighbouring ``True`` in ``hits``, in order."""
    runs, length = [], 0
    for hit in hits:
        if hit:
            length += 1
        elif length:
            runs.append(length)
            length = 0
    if length:
        runs.append(length)
    return runs


def check_options(env_kwargs: dict[str, Any]) -> None:
    """Refuse a policy whose slide is not read around the ball or that meets no figurine."""
    if not env_kwargs.get("slide_around_ball"):
        raise ValueError(
            "the policy's slide is not read around the ball, so a held slide value is no fixed "
            "aim; give a policy trained with slide_around_ball (e.g. 0.015 with slide_skip 0.009)"
        )
    if not env_kwargs.get("obstacles"):
        raise ValueError("the policy was trained without obstacles=True: no lane is shut")


def scan(
    policy: Callable[[np.ndarray], Any],
    reset: Callable[[], None] | None,
    env: gym.Env,
    seed: int,
    grid: np.ndarray,
) -> np.ndarray:
    """Whether ``env``'s ball of ``seed`` is scored with the slide action held at each of
    ``grid``, the spin the policy's."""
    hits = np.zeros(len(grid), bool)
    for i, held in enumerate(grid):
        if reset is not None:
            reset()
        obs, _ = env.reset(seed=seed)
        done, info = False, {}
        while not done:
            action = np.array(policy(obs), np.float32)
            action[0] = held
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
        hits[i] = info.get("goal") == 1
    return hits


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", help="a run folder, a model or builtin:NAME")
    parser.add_argument("--episodes", type=int, default=40, help="seeded balls to look at")
    parser.add_argument("--seed", type=int, default=0, help="the first ball's seed")
    parser.add_argument("--points", type=int, default=201, help="held slide values in [-1, 1]")
    parser.add_argument("--trust", action="store_true", help="load pickled files too")
    args = parser.parse_args(argv)
    if args.points < 2:
        parser.error(f"--points must be at least 2, got {args.points}")
    loaded = foosball_gym.load_policy(args.run, trust=args.trust)
    if loaded.env_id != ENV_ID:
        parser.error(f"{args.run} was trained on {loaded.env_id}; this script plays {ENV_ID}")
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from shot_lanes import straight_lane_open, task_balls  # a script beside this one

    options = task_balls(loaded.env_kwargs)
    try:
        check_options(options)
    except ValueError as error:
        parser.error(str(error))

    grid = np.linspace(-1.0, 1.0, args.points)
    step = float(grid[1] - grid[0])
    env = gym.make(ENV_ID, **options)
    names = list(env.unwrapped.obs_builder.names)  # type: ignore[attr-defined]
    print(f"{args.run}: the slide held at {args.points} values in [-1, 1], {step:.3f} apart")
    print(f"{'ball':>6} {'scoring':>8} {'windows':>8} {'widest':>7} {'straight':>9}")
    shut = scoring = 0
    widest: list[float] = []
    for ball in range(args.seed, args.seed + args.episodes):
        obs, _ = env.reset(seed=ball)
        if straight_lane_open(names, obs):
            continue
        hits = scan(loaded, loaded.reset, env, ball, grid)
        runs = windows(list(hits))
        wide = max(runs, default=0) * step
        near = int(hits[np.abs(grid) <= STRAIGHT + 1e-9].sum())
        strip = "".join("#" if h else "." for h in hits)
        print(f"{ball:>6} {int(hits.sum()):>8} {len(runs):>8} {wide:>7.2f} {near:>9}  {strip}")
        shut += 1
        scoring += bool(hits.any())
        widest.append(wide)
    env.close()
    if shut:
        print(
            f"{shut} shut balls: {scoring} with a held value that scores; widest window, "
            f"median {np.median(widest):.2f}, quartiles {np.percentile(widest, 25):.2f} and "
            f"{np.percentile(widest, 75):.2f} of the action's units"
        )
    else:
        print("no ball among these has its straight lane shut")


if __name__ == "__main__":
    main()
