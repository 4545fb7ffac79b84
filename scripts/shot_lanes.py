"""Where a scoring policy's goals come from when figurines stand in the way.

    python scripts/shot_lanes.py RUN [--episodes 200] [--seed 0] [--csv FILE]

Plays ``Foosball-Score-v0`` with the options the policy was trained with (which must place
obstacles) but for the shares that chose its balls and rods (``obstacle_share``,
``shut_lane_share``), on the task's own seeded balls ``seed .. seed + episodes - 1`` with every
rod standing, and sorts each ball by whether a straight kick along the table would pass every
standing figurine and go in: the aiming keeper's own clearance test
(:func:`foosball_gym.policies.aiming.clearance`), judged on the reset's observation. Each
ball's first shot is the ball's velocity at the first step it runs faster than 1 m/s towards
the goal. It prints the goals for and against, the goals on open and on shut lanes, and how
many first shots left more than 5 degrees off the table's axis, with how many goals began with
one; ``--csv`` writes one row per ball.

``RUN`` is what ``foosball eval`` takes (a run folder, a model, ``builtin:NAME``), or
``scripted`` for the task's scripted keeper, which aims.
"""

from __future__ import annotations

import argparse
import csv
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import astuple, dataclass, fields
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import foosball_gym  # noqa: F401  (registers the environments)
from foosball_gym import table
from foosball_gym.policies.aiming import clearance

ENV_ID = "Foosball-Score-v0"
SHOT_SPEED = 1.0  # m/s towards the goal: the ball has been struck
AIMED = 5.0  # degrees off the table's axis: the shot was aimed, not straight


@dataclass
class Ball:
    seed: int
    lane_open: bool
    goal: int  # +1 scored, -1 into its own goal, 0 neither
    first_shot_degrees: float | None  # None: never struck towards the goal


def straight_lane_open(names: Sequence[str], obs: np.ndarray) -> bool:
    """Whether a straight kick from where the ball lies passes every standing figurine of the
    other team and goes in, as the aiming keeper judges it."""
    blockers = []
    for role in table.ROLES:
        name = f"{table.AWAY}_{role}_slide_pos"
        if name in names:
            rod = table.rod(f"{table.AWAY}_{role}")
            blockers.append((rod.x, rod.figurine_y(float(obs[names.index(name)]))))
    if not blockers:
        raise ValueError(
            f"no figurine stands in the ball's way: the observation places none of the other "
            f"team's rods ({list(names)}); train or evaluate with obstacles=True"
        )
    x, y = float(obs[names.index("ball_x")]), float(obs[names.index("ball_y")])
    return clearance(x, y, 0.0, blockers) > 0.0


def task_balls(env_kwargs: Mapping[str, Any]) -> dict[str, Any]:
    """A run's options with the task's own balls and every rod standing, whatever shares of
    them (``obstacle_share``, ``shut_lane_share``) it trained on."""
    return {k: v for k, v in env_kwargs.items() if k not in ("obstacle_share", "shut_lane_share")}


def play(
    policy: Callable[[np.ndarray], Any],
    env_kwargs: dict[str, Any],
    episodes: int,
    seed: int,
    reset: Callable[[], None] | None = None,
) -> list[Ball]:
    """One :class:`Ball` for each seeded episode the policy plays."""
    env = gym.make(ENV_ID, **env_kwargs)
    try:
        names = list(env.unwrapped.obs_builder.names)  # type: ignore[attr-defined]
        missing = [n for n in ("ball_x", "ball_y", "ball_vx", "ball_vy") if n not in names]
        if missing:
            raise ValueError(f"the observation holds no {', '.join(missing)}: it has {names}")
        vx_at, vy_at = names.index("ball_vx"), names.index("ball_vy")
        balls = []
        for i in range(episodes):
            if reset is not None:
                reset()
            obs, _ = env.reset(seed=seed + i)
            lane_open = straight_lane_open(names, obs)
            shot: float | None = None
            done = False
            info: dict[str, Any] = {}
            while not done:
                obs, _, terminated, truncated, info = env.step(policy(obs))
                done = terminated or truncated
                vx, vy = float(obs[vx_at]), float(obs[vy_at])
                if shot is None and vx > SHOT_SPEED:
                    shot = math.degrees(math.atan2(vy, vx))
            balls.append(Ball(seed + i, lane_open, int(info["goal"]), shot))
        return balls
    finally:
        env.close()


def summary(balls: Sequence[Ball]) -> str:
    """The counts the obstacles' runs are compared by in docs/results/baselines.md."""
    n = len(balls)
    scored = [b for b in balls if b.goal == 1]
    open_lanes = [b for b in balls if b.lane_open]
    shots = [b for b in balls if b.first_shot_degrees is not None]
    aimed = [b for b in shots if abs(b.first_shot_degrees or 0.0) > AIMED]
    angles = sorted(b.first_shot_degrees or 0.0 for b in shots)
    lines = [
        f"balls {n}: scored {len(scored)} ({100 * len(scored) / n:.1f} %), "
        f"into its own goal {sum(b.goal == -1 for b in balls)}",
        f"straight lane open {len(open_lanes)}: scored {sum(b.goal == 1 for b in open_lanes)}",
        f"straight lane shut {n - len(open_lanes)}: "
        f"scored {sum(b.goal == 1 and not b.lane_open for b in balls)}",
    ]
    if shots:
        quartiles = np.percentile(angles, [25, 50, 75])
        lines.append(
            f"first shots {len(shots)}: {len(aimed)} ({100 * len(aimed) / len(shots):.0f} %) more "
            f"than {AIMED:g} degrees off the axis, {sum(b.goal == 1 for b in aimed)} of them "
            f"scored; quartiles of the angle "
            + ", ".join(f"{q:+.1f}" for q in quartiles)
            + " degrees"
        )
    else:
        lines.append("first shots 0: the ball was never struck towards the goal")
    return "\n".join(lines)


def write_csv(balls: Sequence[Ball], path: Path) -> None:
    with open(path, "w", newline="") as out:
        writer = csv.writer(out)
        writer.writerow([f.name for f in fields(Ball)])
        for ball in balls:
            writer.writerow(["" if v is None else v for v in astuple(ball)])


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="a run folder, a model, builtin:NAME, or scripted")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0, help="the first ball's seed")
    parser.add_argument("--csv", type=Path, help="write one row per ball here")
    parser.add_argument("--trust", action="store_true", help="load pickled files too")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")

    if args.run == "scripted":
        env_kwargs: dict[str, Any] = {"ball_start": "resting", "obstacles": True}
        probe = gym.make(ENV_ID, **env_kwargs)
        policy = probe.unwrapped.scripted_policy()  # type: ignore[attr-defined]
        probe.close()
        reset = None
    else:
        loaded = foosball_gym.load_policy(args.run, trust=args.trust)
        if loaded.env_id != ENV_ID:
            parser.error(f"{args.run} was trained on {loaded.env_id}; this script plays {ENV_ID}")
        env_kwargs, policy, reset = task_balls(loaded.env_kwargs), loaded, loaded.reset
    if not env_kwargs.get("obstacles"):
        parser.error(f"{args.run} was trained without obstacles: no lane to sort the balls by")
    try:
        balls = play(policy, env_kwargs, args.episodes, args.seed, reset)
    except ValueError as err:
        parser.error(str(err))
    print(f"{args.run} on balls {args.seed}-{args.seed + args.episodes - 1}")
    print(summary(balls))
    if args.csv is not None:
        write_csv(balls, args.csv)
        print(f"wrote {args.csv}")


if __name__ == "__main__":
    main()
