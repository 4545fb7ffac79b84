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


def _scripted(env_id: str, env_kwargs: dict[str, Any]) -> Any:
    """The scripted baseline of an environment."""
    import gymnasium as gym

    if env_id not in gym.registry:
        raise CliError(
            f"unknown environment {env_id!r}; registered: {', '.join(foosball_gym.ENV_IDS)}"
        )
    try:
        env = gym.make(env_id, **env_kwargs)
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    policy = env.unwrapped.scripted_policy()
    env.close()
    return policy


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
            normalize_reward=args.normalize_reward,
            vec_env=args.vec_env,
            eval_freq=args.eval_freq,
            eval_episodes=args.eval_episodes,
            checkpoint_freq=args.checkpoint_freq,
            selfplay_window=args.selfplay_window,
            selfplay_threshold=args.selfplay_threshold,
            selfplay_pool=args.selfplay_pool,
            target_success=args.target_success,
        )
        for name in (
            "n_steps",
            "batch_size",
            "learning_rate",
            "log_std_init",
            "lr_schedule",
            "target_kl",
            "pretrain_episodes",
        ):
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

    from foosball_gym.training.evaluation import evaluate

    env_kwargs = parse_env_kwargs(args.env_kwarg)
    if args.policy == "scripted":
        env_id = args.target
        policy, name = _scripted(env_id, env_kwargs), "scripted"
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


# ------------------------------------------------------------------------------- play


def _policy_for_play(args: argparse.Namespace) -> tuple[Any, str, dict[str, Any]]:
    """The policy to play, with the environment it was trained on."""
    env_kwargs = parse_env_kwargs(args.env_kwarg)
    if args.model == "scripted":
        if not args.env:
            raise CliError("the scripted policy needs --env ENV_ID")
        return _scripted(args.env, env_kwargs), args.env, env_kwargs
    loaded = _load(args.model)
    env_id = args.env or loaded.env_id
    if env_id is None:
        raise CliError(f"{args.model} does not say its environment; give --env ENV_ID")
    return loaded.policy, env_id, {**loaded.env_kwargs, **env_kwargs}


def cmd_play(args: argparse.Namespace) -> int:
    try:
        from foosball_gym.play.stack import play_real, play_sim
    except ImportError as err:
        raise CliError(
            f'{err}; install the hardware extra: pip install "foosball_gym[hardware]"'
        ) from None
    from foosball_gym.envs.interface import task_interface
    from foosball_gym.hardware.config import ConfigError, load_config
    from foosball_gym.hardware.safety import SafetyError

    policy, env_id, env_kwargs = _policy_for_play(args)
    try:
        if args.table == "sim":
            report = play_sim(
                policy,
                env_id,
                env_kwargs,
                episodes=args.episodes,
                seed=args.seed,
                log_path=args.log,
                latency_s=args.latency,
                status=not args.no_status,
                camera_size=args.camera,
            )
        else:
            config = load_config(args.table)
            report = play_real(
                policy,
                task_interface(env_id, env_kwargs),
                config,
                duration_s=args.duration,
                log_path=args.log,
                latency_s=args.latency,
                status=not args.no_status,
            )
    except (ConfigError, ValueError, OSError) as err:
        raise CliError(str(err)) from None
    except SafetyError as err:
        print(f"\nstopped: {err}", file=sys.stderr)
        return 1
    print()
    if report.episodes:
        print(
            f"{report.episodes} episodes of {env_id}: success {100 * report.success_rate:.1f} %"
            f", goals for {report.goals_for}, against {report.goals_against}"
        )
    if report.ball_error_mm:
        errors = report.ball_error_mm
        print(
            f"ball detection error: mean {sum(errors) / len(errors):.1f} mm, "
            f"max {max(errors):.1f} mm"
        )
    print(report.timing_table())
    return 0


def cmd_calibrate(args: argparse.Namespace) -> int:
    import glob

    import cv2

    from foosball_gym.hardware.config import ConfigError, load_config, save_config
    from foosball_gym.play.stack import calibrate_table
    from foosball_gym.vision import OpenCVSource

    try:
        config = load_config(args.table)
    except ConfigError as err:
        raise CliError(str(err)) from None
    if args.frame:
        frame = cv2.imread(args.frame)
        if frame is None:
            raise CliError(f"cannot read an image from {args.frame}")
    else:
        camera = config.camera
        try:
            source = OpenCVSource(
                camera.get("source", 0), camera.get("width"), camera.get("height")
            )
        except OSError as err:
            raise CliError(str(err)) from None
        got = source.read()
        source.close()
        if got is None:
            raise CliError("the camera gave no frame")
        frame = got[1]
    chessboard = None
    if args.chessboard:
        chessboard = [cv2.imread(p) for p in sorted(glob.glob(args.chessboard))]
        chessboard = [img for img in chessboard if img is not None]
    try:
        pattern = tuple(int(v) for v in args.pattern.lower().split("x"))
        summary = calibrate_table(config, frame, chessboard, pattern, args.square, args.home_side)
    except ValueError as err:
        raise CliError(str(err)) from None
    save_config(config, args.table)
    print(f"camera calibrated: {summary}; saved to {args.table}")
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
        "--normalize-reward",
        action="store_true",
        help="scale rewards by the running spread of returns",
    )
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
        "--lr-schedule",
        choices=["constant", "linear"],
        help="constant, or linear decay to 0 over --timesteps (constant)",
    )
    p.add_argument(
        "--pretrain-episodes",
        type=int,
        metavar="N",
        help="first clone the scripted baseline from N episodes (off)",
    )
    p.add_argument(
        "--target-kl",
        type=float,
        help="end an update's epochs once the policy moved this far (off)",
    )
    p.add_argument(
        "--log-std-init", type=float, help="PPO's initial log standard deviation of actions (0)"
    )
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
    _add_env_arguments(p)
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

    p = sub.add_parser(
        "play",
        help="play a policy on a real table over CAN, or a simulated one",
        description="Run a policy on a table: camera, ball detector, Kalman "
        "filter, policy, safety layer, CANopen drives. --table sim runs the "
        "same stack against a simulated table on a virtual CAN bus.",
    )
    p.add_argument("model", help="a run dir, a model .zip, builtin:NAME, or 'scripted'")
    p.add_argument(
        "--table",
        required=True,
        metavar="CONFIG.yaml|sim",
        help="the table configuration, or 'sim' for the simulated table",
    )
    _add_env_arguments(p)
    p.add_argument(
        "--episodes",
        type=_positive_int,
        default=20,
        help="served balls on the simulated table (20)",
    )
    p.add_argument(
        "--duration", type=float, help="seconds to play on a real table (default: until Ctrl-C)"
    )
    p.add_argument(
        "--latency",
        type=float,
        help="how far ahead the filter predicts, s "
        "(default: the table's estimation.latency_s, else 0.03)",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the simulated table's serves")
    p.add_argument(
        "--camera",
        type=_size,
        default=(640, 360),
        metavar="WxH",
        help="the simulated camera's resolution (640x360)",
    )
    p.add_argument("--log", metavar="FILE.jsonl", help="log every loop to this file")
    p.add_argument("--no-status", action="store_true", help="no live status line")
    p.set_defaults(func=cmd_play)

    p = sub.add_parser(
        "calibrate",
        help="calibrate a table's camera",
        description="Solve the camera's pose from the field's corners (and "
        "its intrinsics from chessboard views) and save it to the table "
        "configuration.",
    )
    p.add_argument("--table", required=True, metavar="CONFIG.yaml")
    p.add_argument("--frame", help="an image of the field (default: a frame from the camera)")
    p.add_argument("--chessboard", metavar="GLOB", help="chessboard images for the intrinsics")
    p.add_argument("--pattern", default="9x6", help="inner corners of the chessboard (9x6)")
    p.add_argument("--square", type=float, default=0.025, help="chessboard square side, m")
    p.add_argument(
        "--home-side",
        choices=["left", "right"],
        default="left",
        help="where the home goal is in the image",
    )
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("envs", help="list the environments and their options")
    p.set_defaults(func=cmd_envs)
    return parser


def _add_env_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", help="environment id, where the model does not say it")
    parser.add_argument(
        "--env-kwarg",
        action="append",
        metavar="KEY=VALUE",
        help="an environment option (repeatable)",
    )


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected WIDTHxHEIGHT, e.g. 640x360, got {text!r}"
        ) from None
    if width < 1 or height < 1:
        raise argparse.ArgumentTypeError(f"width and height must be positive, got {text!r}")
    return width, height


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
