"""The ``foosball`` command: train, eval, play, envs. A thin layer over library functions."""

from __future__ import annotations

import argparse
import ast
import inspect
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import foosball_gym


class CliError(Exception):
    """A bad argument or input found after parsing; reported like argparse's errors."""


def parse_env_kwargs(items: Sequence[str] | None) -> dict[str, Any]:
    """``["KEY=VALUE", ...]`` to a dict; values are Python literals where they parse as one."""
    out: dict[str, Any] = {}
    for item in items or ():
        key, sep, raw = item.partition("=")
        if not sep or not key.isidentifier():
            raise CliError(f"--env-kwarg takes KEY=VALUE (e.g. ball_start=incoming), got {item!r}")
        try:
            out[key] = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            out[key] = raw
    return out


def _load(spec: str) -> Any:
    from foosball_gym.training.models import ModelLoadError, load_policy

    try:
        return load_policy(spec)
    except ModelLoadError as err:
        raise CliError(str(err)) from None


# ------------------------------------------------------------------------------- train


def cmd_train(args: argparse.Namespace) -> int:
    from foosball_gym.training.run import TrainConfig, train

    if args.resume:
        out = Path(args.resume)
        if not (out / "config.json").exists():
            raise CliError(f"--resume {out}: no run there (config.json is missing)")
        config = TrainConfig.load(out / "config.json")
    else:
        if not args.env_id:
            raise CliError("give an environment id (see `foosball envs`) or --resume DIR")
        config = TrainConfig(
            env_id=args.env_id,
            env_kwargs=parse_env_kwargs(args.env_kwarg),
            algo=args.algo,
            timesteps=args.timesteps,
            n_envs=args.n_envs,
            seed=args.seed,
            self_play=args.self_play,
            normalize=not args.no_normalize,
            vec_env=args.vec_env,
            eval_freq=args.eval_freq,
            eval_episodes=args.eval_episodes,
            checkpoint_freq=args.checkpoint_freq,
            selfplay_window=args.selfplay_window,
            selfplay_threshold=args.selfplay_threshold,
            selfplay_pool=args.selfplay_pool,
            target_success=args.target_success,
        )
        for name in ("n_steps", "batch_size", "learning_rate"):
            if getattr(args, name) is not None:
                setattr(config, name, getattr(args, name))
        out = Path(args.out or f"runs/{config.env_id}-seed{config.seed}")
    try:
        result = train(config, out, progress_bar=not args.no_progress, resume=bool(args.resume))
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    print(f"trained {result.timesteps} steps in {result.seconds:.0f} s; run in {result.out}")
    if result.reached:
        print(
            f"reached the target success rate at {int(result.reached['timesteps'])} steps, "
            f"{result.reached['wall_seconds']:.0f} s"
        )
    return 0


# ------------------------------------------------------------------------------- eval


def cmd_eval(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from foosball_gym.training.evaluation import evaluate

    env_kwargs = parse_env_kwargs(args.env_kwarg)
    if args.policy == "scripted":
        env_id = args.target
        if env_id not in gym.registry:
            raise CliError(
                f"unknown environment {env_id!r}; registered: {', '.join(foosball_gym.ENV_IDS)}"
            )
        probe = gym.make(env_id, **env_kwargs)
        policy = probe.unwrapped.scripted_policy()
        probe.close()
        name = "scripted"
    else:
        loaded = _load(args.target)
        env_id = args.env or loaded.env_id
        if env_id is None:
            raise CliError(
                f"{args.target} has no config.json naming its environment; give --env ENV_ID"
            )
        env_kwargs = {**loaded.env_kwargs, **env_kwargs}
        policy, name = loaded.policy, loaded.source
    opponent, opponent_name = None, None
    if args.opponent:
        if args.opponent == "scripted":
            opponent_name = "scripted"
        else:
            opponent, opponent_name = _load(args.opponent).policy, args.opponent
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
        )
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    print(result.table())
    Path(args.json).write_text(json.dumps(result.to_dict(), indent=2))
    print(f"wrote {args.json}" + (f" and {args.video}" if args.video else ""))
    return 0


# ------------------------------------------------------------------------------- envs


def describe_envs() -> str:
    import gymnasium as gym

    from foosball_gym.envs.base import FoosballEnv

    lines = []
    base_params = inspect.signature(FoosballEnv.__init__).parameters
    for env_id in foosball_gym.ENV_IDS:
        spec = gym.spec(env_id)
        env = gym.make(env_id)
        cls = type(env.unwrapped)
        lines.append(
            f"{env_id}  ({spec.max_episode_steps} steps, action {env.action_space.shape}"
            f", observation {env.observation_space.shape})"
        )
        first = (cls.__doc__ or "").strip().splitlines()[0]
        lines.append(f"    {first}")
        params = {**base_params, **inspect.signature(cls.__init__).parameters}
        for name, p in params.items():
            if name in ("self", "layout", "extras", "kwargs") or p.default is inspect._empty:
                continue
            if name.startswith("opponent") and not env.unwrapped.layout.opponent:
                continue
            values = cls.option_grid().get(name)
            allowed = f"  one of {', '.join(map(repr, values))}" if values else ""
            lines.append(f"    {name} = {p.default!r}{allowed}")
        env.close()
        lines.append("")
    return "\n".join(lines)


def cmd_envs(args: argparse.Namespace) -> int:
    print(describe_envs())
    return 0


# ------------------------------------------------------------------------------- parser


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="foosball", description="Train, evaluate and play robot foosball policies."
    )
    parser.add_argument("--version", action="version", version=foosball_gym.__version__)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser(
        "train",
        help="train a policy (PPO or SAC, self-play for two players)",
        description="Train a policy on a registered environment.",
    )
    p.add_argument("env_id", nargs="?", help="environment id, e.g. Foosball-Block-v0")
    p.add_argument("--algo", choices=["ppo", "sac"], default="ppo")
    p.add_argument("--timesteps", type=_positive_int, default=500_000)
    p.add_argument("--n-envs", type=_positive_int, default=8)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--env-kwarg",
        action="append",
        metavar="KEY=VALUE",
        help="an environment option (repeatable), e.g. ball_start=incoming",
    )
    sp = p.add_mutually_exclusive_group()
    sp.add_argument(
        "--self-play",
        dest="self_play",
        action="store_true",
        default=None,
        help="play frozen copies of the learner (default for two-player tasks)",
    )
    sp.add_argument(
        "--no-self-play",
        dest="self_play",
        action="store_false",
        help="play the environment's scripted opponent instead",
    )
    p.add_argument("--out", metavar="DIR", help="run directory (default runs/ENV-seedN)")
    p.add_argument(
        "--resume", metavar="DIR", help="continue the run in DIR from its last checkpoint"
    )
    p.add_argument("--no-normalize", action="store_true", help="do not normalise observations")
    p.add_argument(
        "--vec-env",
        choices=["dummy", "subproc"],
        default="dummy",
        help="environments in this process (dummy) or one process each",
    )
    p.add_argument("--n-steps", type=_positive_int, help="PPO horizon per environment (128)")
    p.add_argument("--batch-size", type=_positive_int, help="minibatch size (256)")
    p.add_argument("--learning-rate", type=float, help="learning rate (1e-3)")
    p.add_argument(
        "--eval-freq", type=_positive_int, default=10_000, help="evaluate every this many steps"
    )
    p.add_argument("--eval-episodes", type=_positive_int, default=50)
    p.add_argument("--checkpoint-freq", type=_positive_int, default=50_000)
    p.add_argument(
        "--selfplay-window",
        type=_positive_int,
        default=100,
        help="games the net score is taken over",
    )
    p.add_argument(
        "--selfplay-threshold",
        type=float,
        default=0.2,
        help="net score above which the opponent is replaced",
    )
    p.add_argument(
        "--selfplay-pool",
        type=_positive_int,
        default=1,
        help="draw opponents from the last K snapshots",
    )
    p.add_argument(
        "--target-success",
        type=float,
        help="stop once an evaluation reaches this success rate (0-1)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser(
        "eval",
        help="evaluate a policy on seeded episodes",
        description="Evaluate a trained model (a run dir, a .zip or builtin:NAME)"
        " or, with --policy scripted, the scripted baseline of ENV_ID.",
    )
    p.add_argument("target", help="MODEL, or ENV_ID with --policy scripted")
    p.add_argument(
        "--policy",
        choices=["scripted"],
        help="evaluate the scripted baseline of the environment TARGET",
    )
    p.add_argument("--env", help="environment id, where the model's run does not say it")
    p.add_argument("--env-kwarg", action="append", metavar="KEY=VALUE")
    p.add_argument("--episodes", type=_positive_int, default=100)
    p.add_argument("--seed", type=int, default=0, help="first episode's seed")
    p.add_argument(
        "--opponent",
        metavar="scripted|MODEL",
        help="the away side in two-player tasks (default: scripted)",
    )
    p.add_argument("--json", default="eval.json", help="write the results here (eval.json)")
    p.add_argument("--video", metavar="FILE.mp4", help="record the first episode")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("envs", help="list the environments and their options")
    p.set_defaults(func=cmd_envs)
    return parser


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except CliError as err:
        parser.exit(2, f"{parser.prog} {args.command}: error: {err}\n")
    except ImportError as err:
        parser.exit(2, f"{parser.prog} {args.command}: error: {err}\n")
    except KeyboardInterrupt:
        parser.exit(130, "interrupted\n")


if __name__ == "__main__":
    sys.exit(main())
