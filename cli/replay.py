"""``foosball replay``: a logged play session as a page to scrub through in a browser."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from .common import CliError, check_writable


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "replay",
        help="replay a logged play session in a browser",
        description="Write a `foosball play --log` session as one self-contained HTML page "
        "(no server, no network): the table from above, the rods and the ball, the estimate "
        "the policy saw against the true ball where the log holds both, a time slider, "
        "play/pause and speed. `foosball eval --replay` writes one for evaluated episodes.",
    )
    p.add_argument("log", metavar="FILE.jsonl", help="a session log of foosball play --log")
    p.add_argument("--html", required=True, metavar="OUT.html", help="the page to write (.html)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from foosball_gym.replay import LogError, check_page_path, recording_from_session, write_html

    try:
        check_page_path(args.html)
    except ValueError as err:
        raise CliError(f"--html {err}") from None
    check_writable("--html", args.html)
    if not Path(args.log).is_file():
        raise CliError(f"{args.log}: no such file")
    try:
        recording = recording_from_session(args.log)
        path = write_html(recording, args.html)
    except LogError as err:
        raise CliError(str(err)) from None
    except OSError as err:
        raise CliError(f"{err.filename or args.log}: {err.strerror or err}") from None
    size = path.stat().st_size
    print(
        f"wrote {path}: {len(recording.episodes)} episodes, {recording.frames} frames, "
        f"{size / 1e3:.0f} kB; open it in a browser"
    )
    return 0
