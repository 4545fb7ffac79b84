"""Shots past defenders that move: which way to kick so that no rod ahead can get a figurine
into the ball's path in the time the ball takes to reach it.

:mod:`foosball_gym.policies.aiming` judges a shot against figurines standing where they are.
A defender that sees the shot coming slides towards it, so here each figurine covers what its
drive can reach before the ball crosses its line (:mod:`foosball_gym.policies.reach`): a shot
crossing a rod's line close to the shooter is judged almost as against standing figurines, one
crossing the keeper's line far away must pass wide of it. A shot's kick speed falls with its
angle (kicks off the rounded end of the foot are weaker), which gives a far defender longer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from foosball_gym import table
from foosball_gym.policies.aiming import (
    ANGLE_ERROR,
    ANGLE_ERROR_SLOPE,
    MAX_ANGLE,
    MIN_ANGLE,
)
from foosball_gym.policies.reach import BLOCK, move_distances

# A ball whose centre crosses the line this far inside a post mostly goes in.
_GOAL = table.GOAL_HALF_WIDTH - 0.005
# Kick speed (m/s) by shot angle (degrees), kicked from the wind-up with the foot's flat or a
# rounded end: measured in the simulator on every rod (within 0.5 m/s of each other).
_SPEED_ANGLES = (0.0, 13.0, 24.0, 36.0, 53.0)
_SPEEDS = (7.2, 7.1, 6.8, 6.0, 3.8)
_STEP = math.radians(1.0)
# Where along the end wall (|y|, m) a corner shot is aimed: the middle of 0.12-0.165 m.
CORNER_MIDDLE = 0.1425
_WALL = table.BALL_LIMIT_Y
# As aiming.path_y: planning with the nominal restitution aimed better than the measured one.
_WALL_RESTITUTION = table.BALL_TABLE_RESTITUTION
# The angles a shot is planned over: straight, and the corner kicks from MIN_ANGLE out (the flat
# face ends abruptly at the corner: the angles between come out straight).
_ALL = np.arange(-MAX_ANGLE, MAX_ANGLE + 1e-9, _STEP)
_ANGLES = np.concatenate([[0.0], _ALL[np.abs(_ALL) >= MIN_ANGLE]])


def kick_speed(angle: float) -> float:
    """The ball's speed (m/s) after a kick at ``angle`` (rad)."""
    return float(np.interp(abs(math.degrees(angle)), _SPEED_ANGLES, _SPEEDS))


def _paths(
    x0: float, y0: float, angles: np.ndarray, xs: Sequence[float]
) -> tuple[list[np.ndarray], np.ndarray]:
    """:func:`~foosball_gym.policies.aiming.path_y` for many angles at once: where each shot
    crosses each x in ``xs`` (increasing, beyond x0), and its slope (dy/dx) at the last."""
    slope = np.tan(angles)
    x = np.full_like(slope, x0)
    y = np.full_like(slope, y0)
    out = []
    for target in xs:
        for _ in range(8):
            reach = y + slope * (target - x)
            over = (np.abs(reach) > _WALL) & (slope != 0)
            if not over.any():
                break
            wall = np.copysign(_WALL, slope[over])
            x[over] += (wall - y[over]) / slope[over]
            y[over] = wall
            slope[over] *= -_WALL_RESTITUTION
        reach = y + slope * (target - x)
        out.append(reach)
        x = np.full_like(slope, target)
        y = reach
    return out, slope


def margins(
    x0: float,
    y0: float,
    angles: np.ndarray,
    defenders: Sequence[tuple[table.Rod, float]],
    react: bool = True,
) -> np.ndarray:
    """By how much (m) shots from (x0, y0) at ``angles`` pass the reach of every defender ahead
    and stay inside the goal mouth; negative where they can be blocked or miss.

    Args:
        x0: where the ball is struck along the table (home frame, attacking +x).
        y0: where it is struck across the table.
        angles: the shots' directions from +x (rad).
        defenders: the other team's rods with their prismatic values, as the home side sees
            them (``table.AWAY`` rods).
        react: the defenders move to block once the ball is struck; False: they stand.
    """
    angles = np.asarray(angles, dtype=float)
    ahead = sorted(((r, s) for r, s in defenders if r.x > x0), key=lambda d: d[0].x)
    ys, slope = _paths(x0, y0, angles, [r.x for r, _ in ahead] + [table.BALL_LIMIT_X])
    speed = np.interp(np.degrees(np.abs(angles)), _SPEED_ANGLES, _SPEEDS) * np.cos(angles)
    end = ys[-1]
    at_line = end + slope * (table.GOAL_LINE_X - table.BALL_LIMIT_X)
    worst = _GOAL - np.abs(at_line)
    for (rod, slide), y in zip(ahead, ys):
        move = move_distances(rod.role, (rod.x - x0) / speed) if react else 0.0
        lows, highs = rod.figurine_y(-rod.slide_limit), rod.figurine_y(rod.slide_limit)
        for fy, one, other in zip(rod.figurine_y(slide), lows, highs):
            # Where this figurine can get to: within its reach and its travel.
            a = np.maximum(fy - move, min(one, other))
            b = np.minimum(fy + move, max(one, other))
            gap = np.where(y < a, a - y, np.where(y > b, y - b, -np.minimum(y - a, b - y)))
            worst = np.minimum(worst, gap - BLOCK)
    return worst


def plan_reacting_shot(
    x0: float,
    y0: float,
    defenders: Sequence[tuple[table.Rod, float]],
    react: bool = True,
) -> tuple[float, float]:
    """The shot angle (rad) whose worst margin over its likely error is widest, and that margin
    (m; negative: every shot can be blocked).

    Corner kicks come out a few degrees off, more at wider angles (as in
    :func:`~foosball_gym.policies.aiming.plan_shot`); straighter shots win ties. ``react``:
    as :func:`margins`.
    """
    angles = _ANGLES
    error = ANGLE_ERROR + ANGLE_ERROR_SLOPE * np.abs(angles)
    # Each angle's margin does not depend on the others: all three judged in one pass.
    judged = np.concatenate([angles - error, angles, angles + error])
    score = margins(x0, y0, judged, defenders, react).reshape(3, -1).min(axis=0)
    score -= 0.001 * np.abs(angles)
    best = int(np.argmax(score))
    return float(angles[best]), float(score[best] + 0.001 * abs(angles[best]))


def plan_shot_past(
    x0: float, y0: float, defenders: Sequence[tuple[table.Rod, float]], corner: bool = False
) -> float:
    """The shot angle (rad) from (x0, y0) that no defender can reach in time where there is
    one; where there is none, the one that passes widest of them where they stand, which makes
    them move.

    A shot every reacting defender can block is not made better by aiming it where they block
    it least badly: that chose wide bank shots, which came back off the far keeper and along
    the side wall behind the shooter's own keeper (the attacking keeper then lost to one that
    stands still, 9 goals to 13 in 10 matches).

    ``corner``: where the last defender stands in the ball's way (it follows the ball, and so
    will follow a shot), a bank shot into the corner beside the goal (:func:`corner_shot`).
    """
    angle, margin = plan_reacting_shot(x0, y0, defenders)
    if margin > 0.0:
        return angle
    if corner and defenders:
        last, slide = max(defenders, key=lambda d: d[0].x)
        if min(abs(f - y0) for f in last.figurine_y(slide)) < BLOCK:
            return corner_shot(x0, y0, last, slide)
    return plan_reacting_shot(x0, y0, defenders, react=False)[0]


def corner_shot(x0: float, y0: float, keeper: table.Rod, slide: float) -> float:
    """A bank shot that reaches the end wall beside the goal, coming back towards its middle,
    on the side the keeper is further from.

    A keeper that follows the ball goes with it to the edge of its travel, and the ball,
    back off the end wall, meets the back of its foot and goes in: measured against the
    kicking keeper (``scripted:1``) from a resting ball 1 m away, the shots of a window about
    2 degrees wide on either side score, those that reach the end wall 0.12-0.165 m from the
    middle (as :func:`margins` draws their paths).
    """
    side = -1.0 if keeper.figurine_y(slide)[0] > 0 else 1.0
    angles = _ALL[np.sign(_ALL) == side]  # off the side wall on that side, coming back in
    ys, slope = _paths(x0, y0, angles, [table.BALL_LIMIT_X])
    inward = ys[-1] * slope < 0
    miss = np.where(inward, np.abs(side * ys[-1] - CORNER_MIDDLE), np.inf)
    return float(angles[int(np.argmin(miss))])
