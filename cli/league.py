"""``foosball league``: rate a self-play run's generations against each other and the field."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import (
    CliError,
    add_trust_argument,
    check_directory,
    is_scripted,
    load_model,
    parse_env_kwargs,
    positive_int,
    scripted,
    seed,
)

MOST_GENERATIONS = 8


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "league",
        help="Elo ratings of a self-play run's generations, round-robin",
        description="Play every saved generation of a self-play run, its final policy, the "
        "scripted side and any --add MODEL against each other, round-robin, and rate them "
        "(Elo, maximum likelihood, 95 % bootstrap intervals). Prints the table and writes "
        "league.json and league.png into the run directory (or --out). Without a run, the "
        "--add players and the scripted side of --env play (e.g. the scripted ladder: --add "
        "scripted:0 --add scripted:1 ...).",
    )
    p.add_argument(
        "run",
        nargs="?",
        help="a self-play run directory (foosball train on a two-player task); leave it out "
        "to rate only the --add players and the scripted side of --env",
    )
    p.add_argument("--env", metavar="ENV_ID", help="the two-player game of a league without a run")
    p.add_argument(
        "--add",
        action="append",
        default=[],
        metavar="MODEL",
        help="another player: a run dir, a model .zip, builtin:NAME, or scripted:N (level N of "
        "the game's scripted ladder) (repeatable)",
    )
    p.add_argument(
        "--games", type=positive_int, default=20, help="games each pair plays (%(default)s)"
    )
    p.add_argument(
        "--generations",
        type=positive_int,
        default=MOST_GENERATIONS,
        metavar="N",
        help="rate at most N generations, evenly spread, first and last kept (%(default)s)",
    )
    p.add_argument("--seed", type=seed, default=0, help="seed of the first game (%(default)s)")
    p.add_argument(
        "--no-scripted", action="store_true", help="leave the scripted side out of the league"
    )
    p.add_argument(
        "--sampled",
        action="store_true",
        help="the run's generations and final policy sample their actions, as the opponents "
        "of a run trained with --selfplay-sampled did, instead of acting on their mean "
        "(seeded by --seed; --add players too)",
    )
    p.add_argument(
        "--env-kwarg",
        action="append",
        metavar="KEY=VALUE",
        help="an environment option over the run's (repeatable), e.g. stagnation_steps=60 "
        "to end a game as a draw once the ball lies still",
    )
    p.add_argument("--out", metavar="DIR", help="where league.json and league.png go (the run)")
    add_trust_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foosball_gym.training import require_train_extra

    require_train_extra()
    from foosball_gym.training.selfplay.league import (
        SCRIPTED,
        Player,
        rising,
        run_league,
        run_players,
        write_league,
    )

    if args.run is None:
        if not args.env or not args.out:
            raise CliError(
                "a league without a run directory needs --env ENV_ID (the game) and --out DIR "
                "(where league.json and league.png go)"
            )
    elif args.env:
        raise CliError(f"--env {args.env}: a run's league plays the run's own game; leave it out")
    out = Path(args.out or args.run)
    # Before the games: the league is written where they end.
    check_directory("--out" if args.out else "RUN", out)
    env_overrides = parse_env_kwargs(args.env_kwarg)
    if args.run is None:
        players: list[Player] = []
        config: dict[str, Any] = {"env_id": args.env, "env_kwargs": {}}
    else:
        try:
            players, config = run_players(
                args.run, args.generations, trust=args.trust_model, sampled=args.sampled
            )
        except ValueError as err:
            raise CliError(str(err)) from None
    env_kwargs = {**config.get("env_kwargs", {}), **env_overrides}
    for spec in args.add:
        if is_scripted(spec):
            players.append(Player(spec, scripted(config["env_id"], env_kwargs, spec=spec)))
            continue
        loaded = load_model(spec, args.trust_model)
        if args.sampled:
            if not hasattr(loaded.policy, "deterministic"):
                raise CliError(f"{spec} cannot sample its actions (an rllib policy); leave it out")
            loaded.policy.deterministic = False
        players.append(Player(spec, loaded.whole_action()))
    if args.sampled:
        import torch

        # The players' sampling draws from torch's generator: seeded, a league is repeatable.
        torch.manual_seed(args.seed)
    if not args.no_scripted:
        players.append(Player(SCRIPTED, None))
    pairs = len(players) * (len(players) - 1) // 2
    print(
        f"league of {len(players)} players on {config['env_id']}: {pairs} pairs x "
        f"{args.games} games"
    )
    try:
        league = run_league(
            players,
            config["env_id"],
            env_kwargs,
            games=args.games,
            seed=args.seed,
            progress=print,
        )
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    print(league.table())
    trend = rising(league)
    if trend == trend:  # not NaN
        print(f"rank correlation of rating with training steps: {trend:+.2f}")
    try:
        json_path, png = write_league(league, out)
    except OSError as err:
        raise CliError(
            f"{'--out' if args.out else 'RUN'} {out} cannot be written: {err.strerror}"
        ) from None
    print("wrote " + " and ".join(str(p) for p in (json_path, png) if p))
    return 0
