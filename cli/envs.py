"""``foosball envs [ENV_ID]``: list the environments, or one, and their options."""

from __future__ import annotations

import argparse
from typing import Any

from .common import CliError


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "envs",
        help="list the environments and their options",
        description="List the registered environments, or only ENV_ID: their spaces, and each "
        "option with its default and, where it takes few values, those.",
    )
    p.add_argument("env_id", nargs="?", metavar="ENV_ID", help="show only this environment")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foosball_gym.registration import describe_envs

    try:
        print(describe_envs(args.env_id))
    except ValueError as err:
        raise CliError(str(err)) from None
    return 0
