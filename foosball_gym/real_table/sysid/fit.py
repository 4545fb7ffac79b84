"""Fitting a table's physics to session logs: the ball, the drives and the camera together.

:func:`fit_logs` reads the logs (:mod:`~foosball_gym.real_table.sysid.logs`), cuts the ball's track
into stretches (:mod:`~foosball_gym.real_table.sysid.segments`), fits the ball
(:mod:`~foosball_gym.real_table.sysid.ball_fit`) and the drives
(:mod:`~foosball_gym.real_table.sysid.drive_fit`), reads the camera's latency
(:mod:`~foosball_gym.real_table.sysid.latency`), and returns what it found as a
:class:`~foosball_gym.real_table.sysid.result.SysidResult`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from foosball_gym.progress import Progress
from foosball_gym.real_table.sysid.ball_fit import fit_ball
from foosball_gym.real_table.sysid.drive_fit import drive_samples, fit_drives, history_for
from foosball_gym.real_table.sysid.latency import camera_latency
from foosball_gym.real_table.sysid.logs import LogError, PlayLog, read_logs
from foosball_gym.real_table.sysid.result import SysidResult
from foosball_gym.real_table.sysid.segments import ball_segments, within_budget
from foosball_gym.sim.replay import BallReplay

#: The most time (s) of the ball's stretches the fit replays whole: longer logs are drawn from
#: evenly, which bounds the time a fit takes however much is logged.
BALL_BUDGET_S = 30.0
#: Fewer drive steps than this do not make a fit.
MIN_DRIVE_STEPS = 30


def fit_logs(
    paths: Sequence[str | Path], ball_budget_s: float = BALL_BUDGET_S, progress: bool = False
) -> SysidResult:
    """Fit the physics of the table the session logs ``paths`` were played on.

    Args:
        paths: session logs of ``foosball play --log``, all of one table.
        ball_budget_s: the most time of the ball's stretches replayed whole.
        progress: show the ball's fit going on standard error (:mod:`foosball_gym.progress`).

    Raises:
        LogError: a log cannot be fitted, one is from another table than the others, or the
            logs never show the ball clear of the rods long enough to fit it.
    """
    return fit(read_logs(paths), ball_budget_s, progress)


def fit(
    logs: list[PlayLog], ball_budget_s: float = BALL_BUDGET_S, progress: bool = False
) -> SysidResult:
    """Fit the physics of the table ``logs`` (read by :func:`read_logs`) were played on;
    ``progress`` as :func:`fit_logs` takes it."""
    segments = ball_segments(logs)
    if not segments:
        names = ", ".join(log.path for log in logs)
        raise LogError(
            f"{names}: the camera never saw the ball clear of the rods for long enough to fit "
            "its physics (0.12 s and 8 frames); log calibration serves: foosball play ... "
            "--table sim --serves calibration, or roll balls by hand on a real table"
        )
    first = logs[0]
    # Kept open with the fit: a plot of it replays the stretches again.
    replay = BallReplay(first.physics_hz, first.control_hz, first.contact_travel)
    # The ball's stretches take most of the time: each start fitted is counted.
    with Progress(0, "sysid", "stretch fits", enabled=progress) as count:
        ball = fit_ball(within_budget(segments, ball_budget_s), replay, count)
    samples = drive_samples(logs, history_for(first.physics_hz, first.control_hz))
    drives = None
    if samples is not None and len(samples) >= MIN_DRIVE_STEPS:
        drives = fit_drives(samples, first.physics_hz, first.control_hz)
    return SysidResult.from_fits(logs, ball, drives, camera_latency(logs), len(segments))
