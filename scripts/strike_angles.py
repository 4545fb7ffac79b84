"""Which way a keeper strikes the ball in keeper against keeper, and which strikes score.

    python scripts/strike_angles.py RUN [--opponent scripted:1] [--episodes 200] [--seed 0]

Plays ``Foosball-KeeperVsKeeper-v0`` with the options the policy was trained with against
``--opponent`` on the seeded serves ``seed .. seed + episodes - 1``. A strike is the learner's
(home) side sending the ball from its own half faster than 1 m/s towards the other goal; its
angle is the ball's direction off the table's axis then. It prints how many strikes there were,
how many left more than 5 degrees off the axis, the angles' quartiles, and the angle of the last
strike before each goal scored.

``RUN`` is what ``foosball eval`` takes (a run folder, a model, ``builtin:NAME``), or
``scripted`` / ``scripted:N`` for a rung of the keepers' ladder.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

import foosball_gym  # noqa: F401  (registers the environments)
from foosball_gym.policies.ladder import is_scripted, parse_scripted

ENV_ID = "Foosball-KeeperVsKeeper-v0"
STRIKE_SPEED = 1.0  # m/s towards the other goal: the ball has been struck
AIMED = 5.0  # degrees off the table's axis: the strike was angled, not straight


@dataclass
class Serve:
    seed: int
    goal: int  # +1 scored, -1 conceded, 0 neither
    strikes: list[float] = field(default_factory=list)  # degrees, in order


def play(
    policy: Callable[[np.ndarray], Any],
    env_kwargs: dict[str, Any],
    opponent: Any,
    episodes: int,
    seed: int,
    reset: Callable[[], None] | None = None,
) -> list[Serve]:
    """One :class:`Serve` for each seeded serve the policy plays against ``opponent``."""
    env = gym.make(ENV_ID, **{**env_kwargs, "opponent": opponent})
    try:
        names = list(env.unwrapped.obs_builder.names)  # type: ignore[attr-defined]
        x_at = names.index("ball_x")
        serves = []
        for i in range(episodes):
            if reset is not None:
                reset()
            obs, _ = env.reset(seed=seed + i)
            serve = Serve(seed + i, 0)
            was_fast = False
            done = False
            info: dict[str, Any] = {}
            while not done:
                obs, _, terminated, truncated, info = env.step(policy(obs))
                done = terminated or truncated
                x, vx, vy = float(obs[x_at]), float(obs[x_at + 2]), float(obs[x_at + 3])
                fast = vx > STRIKE_SPEED
                if fast and not was_fast and x < 0.0:
                    serve.strikes.append(math.degrees(math.atan2(vy, vx)))
                was_fast = fast
            serve.goal = int(info["goal"])
            serves.append(serve)
        return serves
    finally:
        env.close()


def summary(serves: Sequence[Serve]) -> str:
    angles = [a for s in serves for a in s.strikes]
    scored = [s for s in serves if s.goal == 1]
    lines = [
        f"serves {len(serves)}: goals for {len(scored)}, "
        f"against {sum(s.goal == -1 for s in serves)}"
    ]
    if angles:
        aimed = sum(abs(a) > AIMED for a in angles)
        quartiles = np.percentile(angles, [25, 50, 75])
        lines.append(
            f"strikes {len(angles)}: {aimed} more than {AIMED:g} degrees off the axis; "
            "quartiles " + ", ".join(f"{q:+.1f}" for q in quartiles) + " degrees"
        )
    else:
        lines.append("strikes 0: the learner never sent the ball towards the other goal")
    last = [f"{s.strikes[-1]:+.1f}" if s.strikes else "none" for s in scored]
    lines.append("last strike before each goal scored (degrees): " + (", ".join(last) or "-"))
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="a run folder, a model, builtin:NAME, or scripted[:N]")
    parser.add_argument("--opponent", default="scripted:1", help="scripted[:N] (scripted:1)")
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0, help="the first serve's seed")
    parser.add_argument("--trust", action="store_true", help="load pickled files too")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error(f"--episodes must be at least 1, got {args.episodes}")
    if not is_scripted(args.opponent):
        parser.error(f"--opponent must be scripted or scripted:N, got {args.opponent!r}")

    reset = None
    if is_scripted(args.run):
        env_kwargs: dict[str, Any] = {}
        probe = gym.make(ENV_ID, opponent=args.opponent)
        level = parse_scripted(args.run)
        policy = probe.unwrapped.scripted_level(level)  # type: ignore[attr-defined]
        probe.close()
    else:
        loaded = foosball_gym.load_policy(args.run, trust=args.trust)
        if loaded.env_id != ENV_ID:
            parser.error(f"{args.run} was trained on {loaded.env_id}; this script plays {ENV_ID}")
        env_kwargs, policy, reset = dict(loaded.env_kwargs), loaded, loaded.reset
    try:
        serves = play(policy, env_kwargs, args.opponent, args.episodes, args.seed, reset)
    except ValueError as err:
        parser.error(str(err))
    print(
        f"{args.run} against {args.opponent} on serves {args.seed}-{args.seed + args.episodes - 1}"
    )
    print(summary(serves))


if __name__ == "__main__":
    main()
