"""The ``foosball`` command: train, eval, dataset, league, play, replay, calibrate, sysid,
envs, migrate.

One module per command, each a thin layer over library functions with ``add_parser`` (its
options) and ``run`` (parsed options to an exit code); this one assembles the parser and turns
errors into exit codes. Installed as ``foosball_gym.cli`` from the top-level ``cli/`` folder.

Importing it needs neither PyTorch nor the hardware extra: a command imports what it needs
when it runs.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

import foosball_gym

from . import calibrate, dataset, envs, evaluate, league, migrate, play, replay, sysid, train
from .common import CliError, Parser

# In the order ``foosball --help`` lists them.
COMMANDS = (train, evaluate, dataset, league, play, replay, calibrate, sysid, envs, migrate)

__all__ = ["CliError", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(
        prog="foosball", description="Train, evaluate and play robot foosball policies."
    )
    parser.add_argument("--version", action="version", version=foosball_gym.__version__)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``foosball`` with ``argv`` (default: the process's arguments).

    Returns:
        The exit code: 0, or 1 where the safety layer stopped a real table. A bad argument or
        input exits with 2 and one line naming it; Ctrl-C with 130 (``train`` writes a
        checkpoint first, and exits 143 on SIGTERM).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except (CliError, ImportError) as err:
        parser.exit(2, f"{parser.prog} {args.command}: error: {err}\n")
    except KeyboardInterrupt:
        parser.exit(130, "interrupted\n")
