"""``foosball envs``: list the environments and their options."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "envs",
        help="list the environments and their options",
        description="List the registered environments: their spaces, and each option with its "
        "default and, where it takes few values, those.",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foosball_gym.registration import describe_envs

    print(describe_envs())
    return 0
