"""``foosball train``: train a policy on a registered environment, or resume a run.

The options that set a :class:`~foosball_gym.training.config.TrainConfig` field take their
help and the default they show from the field, and an option left out is not passed on, so
the default is written down once, in the library.
"""

from __future__ import annotations

import argparse
import shlex
import signal
from dataclasses import fields
from pathlib import Path
from typing import Any

from foosball_gym.training.config import (
    ALGORITHMS,
    LEARNERS,
    LR_SCHEDULES,
    VEC_ENV_KINDS,
    TrainConfig,
)
from foosball_gym.training.config_file import (
    SHIPPED,
    ConfigFileError,
    load_train_config,
    shipped_configs,
)
from foosball_gym.training.run_dir.files import (
    CONFIG_FILE,
    RLLIB_BACKEND,
    has_checkpoint,
    read_backend,
)
from foosball_gym.training.selfplay.rule import SELFPLAY_RULES

from .common import (
    CliError,
    check_directory,
    parse_env_kwargs,
    positive_int,
    positive_number,
    seed,
    storage_failure,
    whole_number,
)
from .distributed import add_rllib_arguments, run_from_args


def _levels(text: str) -> tuple[int, ...]:
    try:
        levels = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected rung numbers of the scripted ladder separated by commas, e.g. 1,2,3; "
            f"got {text!r}"
        ) from None
    return levels


# The TrainConfig fields offered as options (n_envs as --n-envs), with how the command line
# spells their values.
OPTIONS: dict[str, dict[str, Any]] = {
    "algo": {"choices": ALGORITHMS},
    "timesteps": {"type": positive_int},
    "n_envs": {"type": positive_int},
    "seed": {"type": seed},
    "vec_env": {"choices": VEC_ENV_KINDS},
    "n_steps": {"type": positive_int},
    "batch_size": {"type": positive_int},
    "n_epochs": {"type": positive_int},
    "learning_rate": {"type": positive_number},
    "lr_schedule": {"choices": LR_SCHEDULES},
    "learner": {"choices": LEARNERS},
    "pretrain_episodes": {"type": whole_number, "metavar": "N"},
    "teacher_steps": {"type": whole_number, "metavar": "N"},
    "teacher": {"metavar": "scripted|MODEL"},
    "target_kl": {"type": float},
    "log_std_init": {"type": float},
    "ent_coef": {"type": float},
    "sde_sample_freq": {"type": int, "metavar": "N"},
    "eval_freq": {"type": positive_int},
    "eval_episodes": {"type": positive_int},
    "checkpoint_freq": {"type": positive_int},
    "selfplay_rule": {"choices": SELFPLAY_RULES},
    "selfplay_window": {"type": positive_int},
    "selfplay_threshold": {"type": float},
    "selfplay_pool": {"type": positive_int},
    "selfplay_scripted_share": {"type": float},
    "selfplay_scripted_levels": {"type": _levels, "metavar": "N,N,..."},
    "selfplay_ladder_steps": {"type": whole_number, "metavar": "STEPS"},
    "selfplay_gate": {"type": whole_number, "metavar": "GAMES"},
    "selfplay_stall_games": {"type": whole_number, "metavar": "GAMES"},
    "selfplay_stall_fallback": {"choices": ("none", *SELFPLAY_RULES)},
    "rods_held_share": {"type": float, "metavar": "SHARE"},
    "target_success": {"type": float},
    "video_every": {"type": positive_int, "metavar": "N"},
}
DEFAULT_IN_HELP = ("selfplay_threshold", "learner")
# The boolean fields, set by switches.
SWITCHED = (
    "self_play",
    "normalize",
    "normalize_reward",
    "selfplay_sampled",
    "use_sde",
    "worker_rollouts",
)


def add_parser(subparsers: Any) -> None:
    fields_by_name = {f.name: f for f in fields(TrainConfig)}
    p = subparsers.add_parser(
        "train",
        help="train a policy (PPO or SAC, self-play for two players)",
        description="Train a policy on a registered environment.",
    )
    p.hints["--env"] = "train takes the environment id without --env: foosball train ENV_ID"
    p.add_argument("env_id", nargs="?", help=fields_by_name["env_id"].metadata["help"])
    p.add_argument(
        "--env-kwarg",
        action="append",
        metavar="KEY=VALUE",
        help="an environment option (repeatable), e.g. ball_start=incoming",
    )
    p.add_argument("--out", metavar="DIR", help="run directory (default runs/ENV-seedN)")
    p.add_argument(
        "--resume",
        metavar="DIR",
        help="continue the run in DIR from its last checkpoint (with --timesteps N: on to N "
        "steps in all, past where the run was to stop)",
    )
    shipped = ", ".join(SHIPPED + name for name in shipped_configs())
    p.add_argument(
        "--config",
        metavar="FILE.yaml|builtin:ENV_ID",
        help="training settings from a YAML file: the fields these options set, spelled "
        "n_envs, learning_rate, ..., also net_arch, gamma and the others without an option, "
        "env_kwargs, and env_id (the ENV_ID given here must agree); or a shipped one: "
        f"{shipped}. Options given here override the file; the defaults shown below apply "
        "only where neither sets a value",
    )
    for name, spelling in OPTIONS.items():
        f = fields_by_name[name]
        doc = f.metadata["help"].replace("%", "%%")
        # A default that depends on other options is told in the field's own help.
        shown = "" if name in DEFAULT_IN_HELP else f" ({_shown(f.default)})"
        p.add_argument(f"--{name.replace('_', '-')}", help=doc + shown, **spelling)
    _on_off(
        p,
        "self_play",
        "play frozen copies of the learner (default for two-player tasks)",
        "play the environment's scripted opponent instead",
    )
    p.add_argument(
        "--no-normalize",
        dest="normalize",
        action="store_false",
        default=None,
        help="do not normalise observations",
    )
    _on_off(
        p,
        "normalize_reward",
        fields_by_name["normalize_reward"].metadata["help"] + " (the default)",
        "train on the rewards as the environment gives them",
    )
    _on_off(
        p,
        "use_sde",
        fields_by_name["use_sde"].metadata["help"] + " (off)",
        "explore with a Gaussian independent of the state (where a settings file has use_sde)",
    )
    _on_off(
        p,
        "worker_rollouts",
        fields_by_name["worker_rollouts"].metadata["help"],
        "run the policy in the training process once a step, as SB3 does",
    )
    p.add_argument(
        "--selfplay-sampled",
        action="store_true",
        default=None,
        help=fields_by_name["selfplay_sampled"].metadata["help"],
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_rllib_arguments(p)
    p.set_defaults(func=run)


def _on_off(p: argparse.ArgumentParser, name: str, on_help: str, off_help: str) -> None:
    """--NAME and --no-NAME for a boolean field, unset (None) unless one is given."""
    flag = name.replace("_", "-")
    pair = p.add_mutually_exclusive_group()
    pair.add_argument(f"--{flag}", dest=name, action="store_true", default=None, help=on_help)
    pair.add_argument(f"--no-{flag}", dest=name, action="store_false", help=off_help)


def _shown(default: Any) -> str:
    if default is None:
        return "off"
    if default == ():
        return "none"
    if isinstance(default, float):
        return f"{default:g}"
    return str(default)


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The configuration the options ask for; the fields they leave out keep their default."""
    chosen = {
        name: getattr(args, name)
        for name in (*OPTIONS, *SWITCHED)
        if getattr(args, name) is not None
    }
    env_kwargs = parse_env_kwargs(args.env_kwarg)
    if not args.config:
        return TrainConfig(env_id=args.env_id, env_kwargs=env_kwargs, **chosen)
    try:
        return load_train_config(args.config, args.env_id, chosen, env_kwargs)
    except ConfigFileError as err:
        raise CliError(f"--config {err}") from None
    except (ValueError, TypeError) as err:  # an option's value, checked with the file's
        raise CliError(str(err)) from None


_SWITCH_SPELLING = {
    "self_play": "--self-play/--no-self-play",
    "normalize": "--no-normalize",
    "normalize_reward": "--normalize-reward/--no-normalize-reward",
    "selfplay_sampled": "--selfplay-sampled",
    "use_sde": "--use-sde/--no-use-sde",
    "worker_rollouts": "--worker-rollouts/--no-worker-rollouts",
}


def _settings_given(args: argparse.Namespace) -> list[str]:
    """The options given that a run's own configuration decides (ignored on a resume)."""
    given = ["ENV_ID"] if args.env_id else []
    # --timesteps with --resume extends the run.
    given += [
        f"--{name.replace('_', '-')}"
        for name in OPTIONS
        if getattr(args, name) is not None and name != "timesteps"
    ]
    given += [_SWITCH_SPELLING[name] for name in SWITCHED if getattr(args, name) is not None]
    given += [
        flag for flag, value in (("--env-kwarg", args.env_kwarg), ("--out", args.out)) if value
    ]
    return given


def _backend(run: str) -> str:
    try:
        return read_backend(run)
    except ValueError as err:
        raise CliError(f"--resume {run}: {err}") from None


def run(args: argparse.Namespace) -> int:
    if args.resume and args.config:
        raise CliError(
            f"--config {args.config} with --resume {args.resume}: a run continues with the "
            f"settings in its {CONFIG_FILE}; leave --config out"
        )
    if args.resume and (given := _settings_given(args)):
        raise CliError(
            f"{', '.join(given)} with --resume {args.resume}: a run continues with the settings "
            f"in its {CONFIG_FILE}; leave {'it' if len(given) == 1 else 'them'} out"
        )
    if args.backend == RLLIB_BACKEND or (args.resume and _backend(args.resume) == RLLIB_BACKEND):
        if args.resume and args.timesteps is not None:
            raise CliError(
                f"--timesteps with --resume {args.resume}: an rllib run continues to the "
                "steps it was started with"
            )
        named = args.env_id or args.config
        config = None if args.resume or not named else config_from_args(args)
        return run_from_args(args, config)
    from foosball_gym.training import require_train_extra

    require_train_extra()
    from foosball_gym.training.sb3.trainer import train

    if args.resume:
        out = Path(args.resume)
        if not (out / CONFIG_FILE).exists():
            raise CliError(f"--resume {out}: no run there ({CONFIG_FILE} is missing)")
        try:
            config = TrainConfig.load(out / CONFIG_FILE)
        except (ValueError, TypeError) as err:  # JSONDecodeError is a ValueError
            raise CliError(f"--resume {out}: {err}") from None
        if not has_checkpoint(out):
            print(f"{out} has no checkpoint yet: starting the run over from its {CONFIG_FILE}")
    else:
        if not args.env_id and not args.config:
            raise CliError(
                "give an environment id (see `foosball envs`), --config FILE or --resume DIR"
            )
        config = config_from_args(args)
        out = Path(args.out or f"runs/{config.env_id}-seed{config.seed}")
        check_directory("--out", out)
    try:
        result = train(
            config,
            out,
            progress_bar=not args.no_progress,
            resume=bool(args.resume),
            timesteps=args.timesteps if args.resume else None,
        )
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    except OSError as err:
        raise CliError(storage_failure("--resume" if args.resume else "--out", out, err)) from None
    if result.signal is not None:
        name = signal.Signals(result.signal).name
        print(
            f"stopped by {name} after {result.timesteps} steps; checkpoint written. Continue with: "
            f"foosball train --resume {shlex.quote(str(result.out))}"
        )
        return 128 + result.signal
    print(f"trained {result.timesteps} steps in {result.seconds:.0f} s; run in {result.out}")
    if result.reached:
        print(
            f"reached the target success rate at {int(result.reached['timesteps'])} steps, "
            f"{result.reached['wall_seconds']:.0f} s"
        )
    return 0
