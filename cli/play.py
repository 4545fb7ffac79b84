"""``foosball play``: run a policy on a real table over CAN, or on the simulated one."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from .common import (
    CliError,
    LibraryDefault,
    _has_display,
    add_env_arguments,
    given,
    is_scripted,
    load_model,
    parse_env_kwargs,
    positive_int,
    positive_number,
    seed,
    show_size,
    size,
)

if TYPE_CHECKING:
    from foosball_gym.envs.options import CheckedOptions

PLAY_SIM = "foosball_gym.real_table.play.stack:play_sim"
# A camera's frame takes a few milliseconds to be read out at the least, and one that comes
# half a second late shows a ball long gone; below 1 ms, a number meant in seconds is likelier.
MIN_LATENCY_MS = 1.0
MAX_LATENCY_MS = 500.0
# As foosball_gym.real_table.sysid.excitation names them (which imports numpy: not at --help).
SERVE_PATTERNS = ("task", "calibration")


class _CameraDefault(LibraryDefault):
    """The simulated camera's size, which depends on the clock the table keeps."""

    def __init__(self) -> None:
        super().__init__(PLAY_SIM, "camera_size")

    def __str__(self) -> str:
        try:
            from foosball_gym.real_table.play.stack import LOCKSTEP_CAMERA, REALTIME_CAMERA
        except ImportError:
            return "play_sim's default"
        return (
            f"{show_size(REALTIME_CAMERA)}; {show_size(LOCKSTEP_CAMERA)} with --lockstep "
            "and no window"
        )


def add_parser(subparsers: Any) -> None:
    p = subparsers.add_parser(
        "play",
        help="play a policy on a real table over CAN, or a simulated one",
        description="Run a policy on a table: camera, ball detector, Kalman "
        "filter, policy, safety layer, CANopen drives. --table sim runs the "
        "same stack against a simulated table on a virtual CAN bus.",
    )
    p.add_argument(
        "model",
        help="a run dir, a model .zip, builtin:NAME, 'scripted', or 'scripted:N' (a level of "
        "the game's scripted ladder)",
    )
    p.add_argument(
        "--table",
        required=True,
        metavar="CONFIG.yaml|sim",
        help="the table configuration, or 'sim' for the simulated table",
    )
    add_env_arguments(p)
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=20,
        help="served balls on the simulated table (%(default)s)",
    )
    p.add_argument(
        "--duration",
        type=positive_number,
        help="seconds to play on a real table (default: until Ctrl-C)",
    )
    p.add_argument(
        "--latency",
        type=latency_ms,
        metavar="MS",
        help=f"how far ahead the filter predicts, in milliseconds: 0, or {MIN_LATENCY_MS:g} to "
        f"{MAX_LATENCY_MS:g} (default: the table's estimation.latency_s, else 30 ms)",
    )
    p.add_argument(
        "--seed",
        type=seed,
        default=LibraryDefault(PLAY_SIM, "seed"),
        help="seed of the simulated table's serves: serve K is the ball of episode K of "
        "foosball eval --seed SEED",
    )
    p.add_argument(
        "--camera",
        dest="camera_size",
        type=size,
        default=_CameraDefault(),
        metavar="WxH",
        help="the simulated camera's resolution (%(default)s)",
    )
    clock = p.add_mutually_exclusive_group()
    clock.add_argument(
        "--realtime",
        action="store_const",
        const="realtime",
        dest="clock",
        help="run the simulated table on the wall clock, its camera in a process of its own "
        "(the default, except with --gui)",
    )
    clock.add_argument(
        "--lockstep",
        action="store_const",
        const="lockstep",
        dest="clock",
        help="run the simulated table in lock-step with the loop, on simulated time: "
        "deterministic for a seed, and as slow as the machine makes it",
    )
    p.add_argument(
        "--gui",
        action="store_true",
        help="watch the simulated table in the PyBullet GUI, the serve and the score written "
        "in the window (needs a display); the table runs lock-step paced to the wall clock, "
        "slower where the machine cannot keep up, or with --realtime on the wall clock itself",
    )
    p.add_argument(
        "--human",
        action="store_true",
        help="play the away keeper yourself against the policy, from the keyboard of the GUI "
        "window (implies --gui; the key map is printed at the start); two-player "
        "environments only: Foosball-KeeperVsKeeper-v0, Foosball-FullGame-v0",
    )
    p.add_argument(
        "--human-rod",
        metavar="NAME",
        help="the away rod --human drives: keeper (the default), or in Foosball-FullGame-v0 "
        "also defense, midfield, offense; the others play as the task's opponent (implies "
        "--human)",
    )
    p.add_argument(
        "--serves",
        choices=SERVE_PATTERNS,
        default="task",
        help="what the simulated table serves: the task's own balls, or 'calibration' balls "
        "that roll, slide and bounce off the walls for up to 4 s each, for foosball sysid to "
        "fit the table's physics to (%(default)s)",
    )
    p.add_argument(
        "--view",
        choices=("top", "away"),
        help="where the GUI window looks from: top (straight down, the policy's goal on the "
        "left; the default) or away (along the table from behind the away goal, where the "
        "person playing stands; the keys follow the screen); needs --gui or --human",
    )
    p.add_argument(
        "--log",
        metavar="FILE.jsonl",
        help="log every loop to this file (foosball replay FILE.jsonl --html OUT.html shows it)",
    )
    p.add_argument("--no-status", action="store_true", help="no live status line")
    p.set_defaults(func=run)


def latency_ms(text: str) -> float:
    """``--latency``: milliseconds, 0 or within :data:`MIN_LATENCY_MS`-:data:`MAX_LATENCY_MS`;
    returns seconds."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected milliseconds, got {text!r}") from None
    allowed = f"0, or {MIN_LATENCY_MS:g} to {MAX_LATENCY_MS:g} ms"
    if 0 < value < MIN_LATENCY_MS:
        raise argparse.ArgumentTypeError(
            f"is in milliseconds ({allowed}); {text} ms is {1e3 * value:g} µs: "
            f"did you mean {1e3 * value:g}?"
        )
    if not (value == 0 or MIN_LATENCY_MS <= value <= MAX_LATENCY_MS):
        raise argparse.ArgumentTypeError(f"must be {allowed}, got {text!r}")
    return value / 1e3


def _policy(args: argparse.Namespace) -> tuple[Any, str, dict[str, Any], CheckedOptions]:
    """The policy to play, with the environment it was trained on and its options, checked
    as the environment checks them: resolved once, here, for the whole command."""
    from foosball_gym.policies.ladder import parse_scripted
    from foosball_gym.registration import check_env_options, scripted_for

    env_kwargs = parse_env_kwargs(args.env_kwarg)
    loaded = None
    if is_scripted(args.model):
        if not args.env:
            raise CliError("the scripted policy needs --env ENV_ID")
        env_id = args.env
    else:
        loaded = load_model(args.model, args.trust_model)
        if loaded.recurrent:
            # A table has no episodes to start its memory afresh at, as training had.
            raise CliError(
                f"{args.model} is a recurrent policy (RecurrentPPO), which foosball play does "
                "not run: its memory would span balls where training reset it; rate it with "
                "foosball eval"
            )
        env_id = args.env or loaded.env_id
        if env_id is None:
            raise CliError(f"{args.model} does not say its environment; give --env ENV_ID")
        env_kwargs = {**loaded.env_kwargs, **env_kwargs}
    try:
        checked = check_env_options(env_id, env_kwargs)
        if loaded is None:
            # A table, simulated or real, is seen through a camera and a filter.
            policy = scripted_for(checked, on_table=True, level=parse_scripted(args.model))
        else:
            loaded.check_env(env_id, env_kwargs, checked)
            # A residual plays over the scripted baseline for a table's camera and filter.
            policy = loaded.with_baseline_of(checked, on_table=True)
    except (ValueError, TypeError) as err:
        raise CliError(str(err)) from None
    return policy, env_id, env_kwargs, checked


def _check_human(env_id: str, checked: CheckedOptions, human: str, rod: str | None) -> None:
    """Fail where a person cannot play ``human`` in the environment."""
    from foosball_gym.real_table.play.human import human_rod

    try:
        human_rod(env_id, checked.interface.layout, human)
    except ValueError as err:
        raise CliError(f"{'--human-rod ' + rod if rod else '--human'}: {err}") from None


def run(args: argparse.Namespace) -> int:
    try:
        from foosball_gym.real_table.play.stack import play_real, play_sim
        from foosball_gym.real_table.play.termination import Terminated, catch_termination
    except ImportError as err:
        raise CliError(f'{err}; install the hardware extra: pip install -e ".[hardware]"') from None
    from foosball_gym.real_table.hardware.config import ConfigError, load_config
    from foosball_gym.real_table.hardware.safety import SafetyError
    from foosball_gym.real_table.virtual.viewer_process import WindowError

    human = args.human_rod or ("keeper" if args.human else None)
    gui = args.gui or human is not None
    if args.view and not gui:
        raise CliError("--view chooses where the GUI window looks from: give --gui or --human")
    view = args.view or "top"
    if gui and args.table != "sim":
        raise CliError("--gui and --human play on the simulated table: give --table sim")
    policy, env_id, env_kwargs, checked = _policy(args)
    if human is not None:
        _check_human(env_id, checked, human, args.human_rod)
    if gui and not _has_display():
        option = "--human" if human is not None else "--gui"
        raise CliError(
            f"{option} opens the PyBullet GUI, which needs a display, and DISPLAY is not set; "
            "run under xvfb-run to try it without one"
        )
    if human is not None:
        from foosball_gym.real_table.play.human import key_map_text

        print(
            f"You play the away {human.removeprefix('away_')}, defending the goal "
            f"{'on the right' if view == 'top' else 'nearest you'}. "
            "Click the PyBullet window to give it the keyboard. Keys:"
        )
        print(key_map_text(view), flush=True)
    # The window's own drawing takes a core of two: with it, the table keeps pace in lock-step.
    realtime = args.clock == "realtime" or (args.clock is None and not gui)
    if args.clock and args.table != "sim":
        raise CliError(f"--{args.clock} chooses the simulated table's clock: give --table sim")
    if args.serves != "task" and args.table != "sim":
        raise CliError(
            f"--serves {args.serves} is what the simulated table serves: give --table sim "
            "(on a real table, serve calibration balls by hand: docs/system-identification.md)"
        )
    # SIGTERM and SIGHUP stop the table as Ctrl-C does: brake, switch off, then exit.
    restore_signals = catch_termination()
    try:
        if args.table == "sim":
            report = play_sim(
                policy,
                env_id,
                env_kwargs,
                episodes=args.episodes,
                log_path=args.log,
                latency_s=args.latency,
                status=not args.no_status,
                realtime=realtime,
                gui=gui,
                human=human,
                # A person follows the game at the wall clock's speed; paced lock-step slows
                # down on a machine that cannot keep up instead of tripping the watchdog.
                pace=gui and not realtime,
                view=view,
                serves=args.serves,
                checked=checked,
                **given(args, "seed", "camera_size"),
            )
        else:
            config = load_config(args.table)
            report = play_real(
                policy,
                checked.interface,
                config,
                duration_s=args.duration,
                log_path=args.log,
                latency_s=args.latency,
                status=not args.no_status,
            )
    except (ConfigError, ValueError, OSError, WindowError) as err:
        raise CliError(str(err)) from None
    except SafetyError as err:
        print(f"\nstopped: {err}", file=sys.stderr)
        return 1
    except Terminated as err:
        print(f"\nstopped: {err}", file=sys.stderr)
        return 128 + err.signum
    finally:
        restore_signals()
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
    print(report.timing_summary())
    print(report.timing_table())
    return 0
