"""``foosball sysid``: fit the simulator's physics to a table's session logs."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .common import CliError, check_writable

EXTRA = 'install the sysid extra: pip install -e ".[sysid]"'


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "sysid",
        help="fit the simulator's physics to a table's play logs",
        description="Fit, to session logs of foosball play --log, the physics the environments "
        "take as options: the ball's rolling resistance, restitution and friction, the drives' "
        "gain and latency, and the camera's latency where the logs show it. Prints each value "
        "with its uncertainty, and how far the simulator is from the logs before and after. "
        "Logs worth fitting: foosball play ... --table sim --serves calibration, or balls "
        "rolled by hand on a real table (docs/system-identification.md).",
    )
    p.add_argument("logs", nargs="+", metavar="LOG.jsonl", help="session logs of one table")
    p.add_argument(
        "--json",
        metavar="FILE.json",
        help="also write each fitted value under its quantity's name, with the rest of the fit",
    )
    p.add_argument(
        "--config",
        metavar="FILE.yaml",
        help="also write a training settings file (foosball train --config) whose env_kwargs "
        "make the environment play on the fitted table",
    )
    p.add_argument(
        "--env",
        metavar="ENV_ID",
        help="the environment of --config (default: the one the logs were played in)",
    )
    p.add_argument(
        "--plot",
        metavar="FILE.png",
        help="also draw a logged ball track against the simulator's replays of it before and "
        "after the fit (needs matplotlib)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    for option in ("json", "config", "plot"):
        path = getattr(args, option)
        if path is not None:
            check_writable(f"--{option}", path)
    if args.env is not None and args.config is None:
        raise CliError(f"--env {args.env} names the environment of --config FILE: give that too")
    if args.env is not None:
        from foosball_gym.registration import check_env_id

        try:
            check_env_id(args.env)
        except ValueError as err:
            raise CliError(f"--env: {err}") from None
    try:
        import scipy  # noqa: F401
    except ImportError:
        raise ImportError(f"foosball sysid needs SciPy; {EXTRA}") from None
    if args.config is not None:
        _require("yaml", "--config", "sysid")
    if args.plot is not None:
        _require("matplotlib", "--plot", "train")
        _check_plot_format(args.plot)
    from foosball_gym.real_table.sysid import LogError, read_logs

    try:
        logs = read_logs(args.logs)
    except LogError as err:
        raise CliError(str(err)) from None
    if args.config is not None and args.env is None and logs[0].env_id is None:
        raise CliError(
            f"{logs[0].path} does not name the environment it was played in (a real table's "
            "log): give the environment of --config with --env ENV_ID"
        )
    from foosball_gym.real_table.sysid.fit import fit

    try:
        result = fit(logs, progress=True)
    except LogError as err:
        raise CliError(str(err)) from None
    print(result.summary())
    print(result.table())
    print(result.residual_table())
    flags = result.env_kwarg_flags()
    if flags:
        print(f"the fitted table in foosball play --table sim and foosball eval: {flags}")
    written = []
    if args.json:
        Path(args.json).write_text(json.dumps(result.to_json(), indent=2) + "\n")
        written.append(args.json)
    if args.config:
        Path(args.config).write_text(result.config_text(args.env))
        written.append(args.config)
    if args.plot:
        from foosball_gym.real_table.sysid.plot import plot_fit

        plot_fit(result, args.plot)
        written.append(args.plot)
    if written:
        print("wrote " + ", ".join(written))
    return 0


def _require(module: str, option: str, extra: str) -> None:
    """Fail before the fit, not after it, where ``option`` cannot be written for want of
    ``module``."""
    import importlib

    try:
        importlib.import_module(module)
    except ImportError:
        raise ImportError(f'{option} needs {module}: pip install -e ".[{extra}]"') from None


def _check_plot_format(path: str) -> None:
    """Refuse a --plot file matplotlib cannot write, before the fit rather than after it."""
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    suffix = Path(path).suffix.lower().lstrip(".")
    if suffix not in formats:
        has = f"not .{suffix}" if suffix else "and it has none"
        raise CliError(
            f"--plot {path}: the picture's suffix must be one of "
            f"{', '.join('.' + f for f in sorted(formats))}, {has}"
        )
