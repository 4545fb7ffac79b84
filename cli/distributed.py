"""``foosball train --backend rllib``: the options and the run of the Ray RLlib backend."""

from __future__ import annotations

import argparse
import shlex
import signal
from pathlib import Path

from foosball_gym.training.config import TrainConfig
from foosball_gym.training.rllib.ray_start import INSTALL, require_ray
from foosball_gym.training.run_dir.files import CONFIG_FILE, RLLIB_BACKEND, has_checkpoint

from .common import CliError, check_directory, storage_failure


def _worker_count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a number of env runners, 0 or more: {text!r}")
    return value


def add_rllib_arguments(parser: argparse.ArgumentParser) -> None:
    """``--backend``, ``--num-workers`` and ``--address`` for ``foosball train``."""
    group = parser.add_argument_group("distributed training (--backend rllib)")
    group.add_argument(
        "--backend",
        choices=("sb3", RLLIB_BACKEND),
        default=None,
        help="sb3: Stable-Baselines3 in this process (default); rllib: self-play PPO on "
        f"Ray RLlib, sampling on --num-workers env runners (needs {INSTALL})",
    )
    group.add_argument(
        "--num-workers",
        type=_worker_count,
        default=None,
        metavar="N",
        help="rllib: env runners sampling in parallel, one CPU each (2); 0: in this process",
    )
    group.add_argument(
        "--address",
        default=None,
        metavar="HOST:PORT|auto",
        help="rllib: the Ray cluster's head (HOST:PORT), or auto; default: start a local Ray",
    )


def run_from_args(args: argparse.Namespace, config: TrainConfig | None = None) -> int:
    """``foosball train --backend rllib``: train or resume as the options say; the exit status.

    Args:
        args: ``foosball train``'s parsed options, with :func:`add_rllib_arguments`'s.
        config: the configuration the options ask for; unused with ``--resume``.
    """
    try:
        require_ray()
    except ImportError as err:
        raise CliError(str(err)) from None
    from foosball_gym.training.rllib.trainer import train_rllib

    num_workers = 2 if args.num_workers is None else args.num_workers
    resume = bool(getattr(args, "resume", None))
    if resume:
        out = Path(args.resume)
        if not (out / CONFIG_FILE).exists():
            raise CliError(f"--resume {out}: no run there ({CONFIG_FILE} is missing)")
        try:
            config = TrainConfig.load(out / CONFIG_FILE)
        except (ValueError, TypeError) as err:
            raise CliError(f"--resume {out}: {err}") from None
        if not has_checkpoint(out):
            print(f"{out} has no checkpoint yet: starting the run over from its {CONFIG_FILE}")
    else:
        if config is None:
            raise CliError("give an environment id (see `foosball envs`) or --resume DIR")
        out = Path(getattr(args, "out", None) or f"runs/{config.env_id}-seed{config.seed}")
        check_directory("--out", out)
    try:
        result = train_rllib(
            config, out, num_workers=num_workers, address=args.address, resume=resume
        )
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    except ConnectionError as err:
        raise CliError(f"--address {args.address}: {err}") from None
    except OSError as err:
        raise CliError(storage_failure("--resume" if resume else "--out", out, err)) from None
    if result.signal is not None:
        name = signal.Signals(result.signal).name
        print(
            f"stopped by {name} after {result.timesteps} steps; checkpoint written. Continue "
            f"with: foosball train --backend rllib --resume {shlex.quote(str(result.out))}"
        )
        return 128 + result.signal
    print(
        f"trained {result.timesteps} steps in {result.seconds:.0f} s on {num_workers} env "
        f"runner(s), opponent generation {result.generation}; run in {result.out}"
    )
    if result.reached:
        print(
            f"reached the target success rate at {int(result.reached['timesteps'])} steps, "
            f"{result.reached['wall_seconds']:.0f} s"
        )
    return 0
