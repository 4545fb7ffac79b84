"""``foosball calibrate``: calibrate a table's camera and save it to the table configuration."""

from __future__ import annotations

import argparse
import glob
from pathlib import Path
from typing import Any

from .common import CliError, LibraryDefault, given, grid, show_size

CALIBRATE_TABLE = "foosball_gym.real_table.play.stack:calibrate_table"


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "calibrate",
        help="calibrate a table's camera",
        description="Solve the camera's pose from the field's corners (and "
        "its intrinsics from chessboard views) and save it to the table "
        "configuration.",
    )
    p.add_argument("--table", required=True, metavar="CONFIG.yaml")
    p.add_argument("--frame", help="an image of the field (default: a frame from the camera)")
    p.add_argument("--chessboard", metavar="GLOB", help="chessboard images for the intrinsics")
    p.add_argument(
        "--pattern",
        type=grid,
        default=LibraryDefault(CALIBRATE_TABLE, "pattern", show_size),
        help="inner corners of the chessboard (%(default)s)",
    )
    p.add_argument(
        "--square",
        type=float,
        default=LibraryDefault(CALIBRATE_TABLE, "square"),
        help="chessboard square side, m (%(default)s)",
    )
    p.add_argument(
        "--home-side",
        choices=["left", "right"],
        default=LibraryDefault(CALIBRATE_TABLE, "home_side"),
        help="where the home goal is in the image (%(default)s)",
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not Path(args.table).is_file():
        raise CliError(f"argument --table: no table configuration at {args.table}")
    if args.frame and not Path(args.frame).is_file():
        raise CliError(f"argument --frame: no image at {args.frame}")
    try:
        import cv2

        from foosball_gym.real_table.play.stack import calibrate_table
    except ImportError as err:
        raise CliError(f'{err}; install the hardware extra: pip install -e ".[hardware]"') from None
    from foosball_gym.real_table.hardware.config import ConfigError, load_config, save_config
    from foosball_gym.real_table.vision import OpenCVSource
    from foosball_gym.real_table.vision.calibration import read_image

    try:
        config = load_config(args.table)
    except (ConfigError, OSError) as err:
        raise CliError(str(err)) from None
    if args.frame:
        try:
            frame = read_image(args.frame)
        except (ValueError, OSError) as err:
            raise CliError(f"--frame {err}") from None
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
        try:
            chessboard = [read_image(p) for p in sorted(glob.glob(args.chessboard))]
        except (ValueError, OSError) as err:
            raise CliError(f"--chessboard {err}") from None
    try:
        summary = calibrate_table(
            config, frame, chessboard, **given(args, "pattern", "square", "home_side")
        )
    except (ValueError, cv2.error) as err:
        # OpenCV's messages run over several lines.
        why = " ".join(str(err).split())
        raise CliError(f"not calibrated, {args.table} left as it was: {why}") from None
    save_config(config, args.table)
    print(f"camera calibrated: {summary}; saved to {args.table}")
    return 0
