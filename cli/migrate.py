"""``foosball migrate``: convert a run from before plain model files, once, if trusted."""

from __future__ import annotations

import argparse
from typing import Any

from .common import CliError, add_trust_argument


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "migrate",
        help="convert an older run's pickled files into plain ones",
        description="Rewrite the pickled files of a run from before plain model files "
        "(vecnormalize.pkl, self-play snapshots, SB3's pickled fields) as plain data, so "
        "that it loads without --trust-model. Reading them runs any code they hold, so it "
        "needs --trust-model.",
    )
    p.add_argument("run", metavar="RUN", help="the run directory")
    add_trust_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foosball_gym.training import require_train_extra

    require_train_extra()
    from foosball_gym.training.run_dir.migrate import migrate_run

    try:
        written = migrate_run(args.run, trust=args.trust_model)
    except ValueError as err:
        raise CliError(str(err)) from None
    except Exception as err:  # noqa: BLE001 - whatever a trusted pickle raises, one line
        raise CliError(f"cannot migrate {args.run}: {type(err).__name__}: {err}") from None
    for path in written:
        print(f"wrote {path}")
    print(f"{args.run} loads without --trust-model" + ("" if written else " (nothing to convert)"))
    return 0
