"""A picture of a fit: a logged ball track against the simulator's replay of it, under the
default physics and the fitted one (``foosball sysid --plot``). Needs matplotlib."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from foosball_gym import table
from foosball_gym.real_table.sysid.ball_fit import BallFit, window_track, windows
from foosball_gym.real_table.sysid.result import QUANTITIES, SysidResult

# A window whose first stretch is shorter than this (s) shows its start too briefly to carry the
# ball through a bounce well: another is drawn where there is one.
_SHORTEST_LEAD_S = 0.3


def plot_fit(result: SysidResult, path: str | Path) -> None:
    """Draw the stretch of the logs the fit changed most (one with a wall bounce where there
    is one) over the table, with the replays before and after the fit, and their distance from
    the camera over time; write it to ``path`` (its suffix says the format)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ball = result.ball
    if ball is None:
        raise ValueError("this result holds no fit of the ball to draw")
    window = _most_changed(ball)
    problem = ball.problem
    seen = np.concatenate([problem.segments[i].xy for i in window])
    times, before = window_track(
        problem, ball.physics(False), ball.starts_before[window[0]], window
    )
    _, after = window_track(problem, ball.physics(True), ball.starts_after[window[0]], window)
    fine = np.linspace(0.0, times[-1], 400)
    _, before_line = window_track_at(ball, window, False, fine)
    _, after_line = window_track_at(ball, window, True, fine)

    figure, (top, errors) = plt.subplots(1, 2, figsize=(11, 4.2), width_ratios=(1.6, 1))
    hx, hy = table.FIELD_HALF_LENGTH, table.FIELD_HALF_WIDTH
    top.plot([-hx, hx, hx, -hx, -hx], [-hy, -hy, hy, hy, -hy], color="0.3", lw=1.5)
    for side in (-1, 1):
        top.plot(
            [side * hx] * 2, [-table.GOAL_HALF_WIDTH, table.GOAL_HALF_WIDTH], color="0.3", lw=4
        )
    top.plot(
        before_line[:, 0],
        before_line[:, 1],
        "--",
        color="tab:red",
        lw=1.2,
        label="simulated, default physics",
    )
    top.plot(
        after_line[:, 0],
        after_line[:, 1],
        "-",
        color="tab:blue",
        lw=1.2,
        label="simulated, fitted physics",
    )
    top.plot(seen[:, 0], seen[:, 1], ".", color="black", ms=3, label="camera (logged)")
    top.set_aspect("equal")
    top.set_xlim(-hx - 0.03, hx + 0.03)
    top.set_ylim(-hy - 0.03, hy + 0.03)
    top.set_xlabel("x (m)")
    top.set_ylabel("y (m)")
    top.legend(loc="lower left", fontsize=8)
    top.set_title("a logged ball track and the simulator's replays of it")
    for track, style, colour, name in (
        (before, "--", "tab:red", "default"),
        (after, "-", "tab:blue", "fitted"),
    ):
        errors.plot(times, 1e3 * np.hypot(*(track - seen).T), style, color=colour, label=name)
    errors.set_xlabel("time (s)")
    errors.set_ylabel("replay - camera (mm)")
    errors.set_yscale("log")
    errors.legend(fontsize=8)
    errors.set_title("distance from the camera")
    fitted = ", ".join(
        f"{k} {result.values[k]:.3g} (default {QUANTITIES[k][0]:.3g})"
        for k in ("rolling_resistance", "ball_restitution", "ball_friction")
        if k in result.values
    )
    figure.suptitle(f"fitted: {fitted}", fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=110)
    plt.close(figure)


def window_track_at(
    ball: BallFit, window: list[int], fitted: bool, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A window's replay at any ``times`` after its first frame."""
    starts = ball.starts_after if fitted else ball.starts_before
    return times, ball.problem.track(ball.physics(fitted), window[0], starts[window[0]], times)


def _most_changed(ball: BallFit) -> list[int]:
    """The window whose replay the fit brought nearest the camera, by how far it was."""
    problem = ball.problem
    found = windows(problem, ball.kept)
    led = [w for w in found if len(w) == 2 and problem.segments[w[0]].duration >= _SHORTEST_LEAD_S]
    best, gain = found[0], -np.inf
    for window in led or found:
        seen = np.concatenate([problem.segments[i].xy for i in window])
        change = 0.0
        for fitted, sign in ((False, 1.0), (True, -1.0)):
            starts = ball.starts_after if fitted else ball.starts_before
            _, track = window_track(problem, ball.physics(fitted), starts[window[0]], window)
            change += sign * float(np.sqrt(np.mean((track - seen) ** 2)))
        if change > gain:
            best, gain = window, change
    return best
