"""Where a full-game team from nothing lets its goals in: the team with parts of its action
replaced.

Plays a team whose slides are read around the ball (``slide_around_ball``), a trained run or
the action 0 of ``builtin:full-game-scratch``'s action space, against a rung of the ladder in
continuous one-minute matches (seeds 0..N-1), as it is and with:

- the keeper's and the defence's spins held at 0, their feet down;
- every slide at where the ball will cross the rod's line (the kicking team's block: the
  ball's straight path, off the side walls, while it comes towards the rod), as far as the
  band reaches;
- both.

``--kicks`` also gives the midfield and offence the kicking team's spins: they swing through at
a slow ball in reach in front of them, and lift their feet for a ball behind them moving
forward. A replaced part that closes the goal says where the team's own action let the goals
in.

    python benchmarks/full_game_parts.py [RUN] [--opponent scripted:1] [--matches 10]
        [--band 0.1 --skip 0] [--kicks]
"""

from __future__ import annotations

import argparse
from collections.abc import Callable

import numpy as np

from foosball_gym import table
from foosball_gym.evaluation import evaluate
from foosball_gym.policies.scripted import ScriptedTeam
from foosball_gym.registration import check_env_options
from foosball_gym.training.config_file import read_config_file

ENV = "Foosball-FullGame-v0"
RODS = [f"{table.HOME}_{role}" for role in ("keeper", "defense", "midfield", "offense")]
CONDITIONS = (
    ("as it is", False, False),
    ("keeper and defence spins at 0", True, False),
    ("slides at the ball's crossing", False, True),
    ("both", True, True),
)


def slide_action(offset: float, band: float, skip: float) -> float:
    """The slide action that puts the figurine ``offset`` (m) beside the ball: the inverse of
    the environment's reading of an action around the ball."""
    if abs(offset) <= skip / 2:
        return 0.0
    # Nearer the ball than the skip, the skip is the nearest place an action other than 0 reaches.
    beyond = max(abs(offset) - skip, 1e-9)
    return float(np.clip(np.sign(offset) * beyond / band, -1.0, 1.0))


def parts(
    team: Callable[[np.ndarray], np.ndarray],
    names: list[str],
    band: float,
    skip: float,
    back_still: bool,
    crossing: bool,
    kicks: bool,
) -> Callable[[np.ndarray], np.ndarray]:
    """``team`` with the parts asked for replaced by the kicking team's."""
    kicking = ScriptedTeam(names, RODS, joints="both")
    ball = [names.index(f"ball_{k}") for k in ("x", "y", "vx", "vy")]

    def play(obs: np.ndarray) -> np.ndarray:
        action = np.array(team(obs), dtype=np.float32)
        x, y, vx, vy = (float(obs[i]) for i in ball)
        for i, rod in enumerate(kicking.rods):
            if crossing:
                offset = ScriptedTeam.target_y(rod, x, y, vx, vy) - y
                action[2 * i] = slide_action(offset, band, skip)
            if back_still and i < 2:
                action[2 * i + 1] = 0.0
            if kicks and i >= 2:
                # Without the rod's joint values the kicking team swings at once, unwound.
                spin = kicking.spin_for(rod, x, y, vx, vy, None)
                action[2 * i + 1] = spin / table.SPIN_LIMIT
        return action

    return play


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", nargs="?", help="a trained run (default: the action 0)")
    parser.add_argument("--opponent", default="scripted:1")
    parser.add_argument("--matches", type=int, default=10)
    parser.add_argument("--band", type=float, help="the action 0's slide_around_ball")
    parser.add_argument("--skip", type=float, help="the action 0's slide_skip")
    parser.add_argument("--kicks", action="store_true", help="midfield and offence kick")
    args = parser.parse_args()
    if args.run:
        from foosball_gym.training.loading.loader import load_policy

        policy = load_policy(args.run)
        options = dict(policy.env_kwargs)
        team: Callable[[np.ndarray], np.ndarray] = policy
        if args.band is not None or args.skip is not None:
            parser.error("--band and --skip set the action 0's options; a run has its own")
    else:
        options = dict(read_config_file("builtin:full-game-scratch")["env_kwargs"])
        if args.band is not None:
            options["slide_around_ball"] = args.band
        if args.skip is not None:
            options["slide_skip"] = args.skip

        def team(obs: np.ndarray) -> np.ndarray:
            return np.zeros(8, dtype=np.float32)

    band = float(options.get("slide_around_ball") or 0.0)
    if not band:
        parser.error("the team's slides must be read around the ball (slide_around_ball)")
    skip = float(options.get("slide_skip", 0.0))
    options["continuous"] = True
    names = list(check_env_options(ENV, options).interface.builder.names)
    print(f"{args.run or 'the action 0'} (band {band}, skip {skip}) against {args.opponent}")
    print(f"{'condition':<34} {'for':>4} {'against':>8}")
    for name, back_still, crossing in CONDITIONS:
        player = parts(team, names, band, skip, back_still, crossing, args.kicks)
        result = evaluate(
            player, ENV, options, episodes=args.matches, seed=0, opponent=args.opponent
        )
        print(f"{name:<34} {result.goals_for:>4} {result.goals_against:>8}")


if __name__ == "__main__":
    main()
