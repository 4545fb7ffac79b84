"""``foosball eval``: evaluate a trained model, or a scripted baseline, on seeded episodes.

Scripts read two of the lines it prints, ``success rate N % (95 % CI a - b %)`` and
``goals for / against X / Y``: :meth:`~foosball_gym.evaluation.EvalResult.table` writes them.
"""

from __future__ import annotations

import argparse
import inspect
import json
from pathlib import Path
from typing import Any

from foosball_gym.evaluation import evaluate, option_sources, video_format

from .common import (
    CliError,
    add_env_arguments,
    check_writable,
    is_scripted,
    load_model,
    parse_env_kwargs,
    positive_int,
    scripted,
    scripted_spec,
    seed,
)


def add_parser(subparsers: Any) -> None:
    defaults = inspect.signature(evaluate).parameters
    p = subparsers.add_parser(
        "eval",
        help="evaluate a policy on seeded episodes",
        description="Evaluate a trained model (a run dir, a .zip of any SB3 or sb3-contrib"
        " algorithm, an RL Zoo run or builtin:NAME) or, with --policy scripted, the scripted"
        " baseline of ENV_ID (scripted:N: level N of its scripted ladder, in the two games).",
    )
    p.add_argument("target", help="MODEL, or ENV_ID with --policy scripted")
    p.add_argument(
        "--policy",
        type=scripted_spec,
        metavar="scripted|scripted:N",
        help="evaluate the scripted baseline of the environment TARGET, or level N of its "
        "scripted ladder",
    )
    add_env_arguments(p)
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=defaults["episodes"].default,
        help="seeded episodes (%(default)s)",
    )
    p.add_argument(
        "--seed", type=seed, default=defaults["seed"].default, help="first episode's seed"
    )
    p.add_argument(
        "--opponent",
        metavar="scripted|scripted:N|MODEL",
        help="the away side in two-player tasks: the scripted team (the default), level N of "
        "the scripted ladder, or a model",
    )
    p.add_argument(
        "--json", metavar="FILE.json", help="also write the results here (default: nowhere)"
    )
    p.add_argument(
        "--video",
        metavar="FILE.mp4|FILE.gif",
        help="record the first episode(s) into this file, .mp4 or .gif by its suffix",
    )
    p.add_argument(
        "--video-episodes",
        type=positive_int,
        metavar="N",
        help="record the first N episodes, one after the other, into --video "
        f"({defaults['video_episodes'].default}; at most --episodes)",
    )
    p.add_argument(
        "--video-stride",
        type=positive_int,
        metavar="N",
        help="keep every Nth frame of --video, which still plays in real time "
        "(default: every frame for .mp4, about 20 a second for .gif)",
    )
    p.add_argument(
        "--replay",
        metavar="OUT.html",
        help="write every episode into this page, to replay in a browser (foosball replay)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.json is not None:
        check_writable("--json", args.json)
    if args.video is not None:
        check_writable("--video", args.video)
        try:
            video_format(args.video)
        except ValueError as err:
            raise CliError(f"--video {err}") from None
    else:
        # Without a video they would do nothing, and say nothing about it.
        for option, value in (
            ("--video-episodes", args.video_episodes),
            ("--video-stride", args.video_stride),
        ):
            if value is not None:
                raise CliError(f"{option} {value} needs --video FILE to record into")
    if args.replay is not None:
        from foosball_gym.replay import check_page_path

        check_writable("--replay", args.replay)
        try:
            check_page_path(args.replay)
        except ValueError as err:
            raise CliError(f"--replay {err}") from None
    video_episodes = args.video_episodes or (
        inspect.signature(evaluate).parameters["video_episodes"].default
    )
    if video_episodes > args.episodes:
        raise CliError(
            f"--video-episodes {video_episodes} is more than --episodes {args.episodes}: "
            "only episodes that run can be recorded"
        )
    env_kwargs = parse_env_kwargs(args.env_kwarg)
    sources = option_sources({}, env_kwargs)
    if args.policy:
        env_id = args.target
        policy, name = scripted(env_id, env_kwargs, spec=args.policy), args.policy
    else:
        loaded = load_model(args.target, args.trust_model)
        env_id = args.env or loaded.env_id
        if env_id is None:
            raise CliError(
                f"{args.target} has no config.json naming its environment; give --env ENV_ID"
            )
        sources = option_sources(loaded.env_kwargs, env_kwargs)
        env_kwargs = {**loaded.env_kwargs, **env_kwargs}
        policy, name = loaded, loaded.source
    opponent, opponent_name = None, None
    if args.opponent:
        if is_scripted(args.opponent):
            # The environment builds it: set_opponent takes the name of a scripted team.
            opponent, opponent_name = args.opponent, args.opponent
        else:
            opponent = load_model(args.opponent, args.trust_model)
            opponent_name = args.opponent
    try:
        result = evaluate(
            policy,
            env_id,
            env_kwargs,
            episodes=args.episodes,
            seed=args.seed,
            opponent=opponent,
            policy_name=name,
            opponent_name=opponent_name,
            video=args.video,
            video_episodes=video_episodes,
            video_stride=args.video_stride,
            replay=args.replay,
            option_sources=sources,
            progress=True,
        )
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    except OSError as err:  # the video cannot be written after all
        raise CliError(f"--video {args.video}: {err}") from None
    print(result.table())
    written = [path for path in (args.json, args.video, args.replay) if path]
    if args.json:
        try:
            Path(args.json).write_text(json.dumps(result.to_dict(), indent=2))
        except OSError as err:
            raise CliError(f"--json {args.json} cannot be written: {err.strerror}") from None
    if written:
        print("wrote " + " and ".join(written))
    return 0
