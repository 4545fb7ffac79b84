"""Aimed shots: which way to send the ball past the other team's figurines, and how.

A figurine's leg is flat in front, 18 mm wide, with rounded ends. Struck with the flat, the ball
leaves straight along +x; struck with a rounded end, at an angle that grows with the sideways
offset between ball and figurine at the moment of the kick. The table below was measured in the
simulator (``foosball_gym.sim.probes.corner_kick``, physics revision 2) by kicking a resting
ball from the wind-up with the keeper at each offset; past 0.026 m the kick is too weak to aim.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from foosball_gym import table

# Ball-minus-figurine y offset (m) -> shot angle from +x (degrees).
_OFFSETS = np.arange(0.009, 0.0265, 0.001)
_ANGLES = np.array(
    [0.0, 2.7, 5.5, 8.4, 9.3, 13.6, 16.7, 19.7, 22.6, 25.4, 28.4, 31.1, 33.7, 39.4, 41.7, 45.2]
    + [51.2, 52.9]
)
MAX_ANGLE = math.radians(float(_ANGLES[-1]))
MIN_ANGLE = math.radians(10.0)
# The error a kick at a given angle is allowed when its lane is judged (chosen by scoring over
# obstacle layouts), and the clearance beyond which a wider lane is no better.
ANGLE_ERROR = math.radians(1.0)
ANGLE_ERROR_SLOPE = 0.1
CLEAR_ENOUGH = 0.02

_WALL = table.BALL_LIMIT_Y
# A ball whose centre crosses the line within the opening is a goal; one that grazes a post
# mostly goes in, so the lane only has to keep the centre a little inside.
_GOAL = table.GOAL_HALF_WIDTH - 0.005
# Half the width a figurine blocks: its leg's half width plus the ball's radius.
_BLOCK = table.FIGURINE_LEG_HALF_WIDTH + table.BALL_RADIUS
# A fast bank shot keeps only about a quarter of its sideways speed in the simulator, but
# planning with that chose steeper, less accurate kicks and scored less (40 % against 45 %
# over 300 obstacle layouts) than planning with the nominal half.
_WALL_RESTITUTION = table.BALL_TABLE_RESTITUTION


def offset_for_angle(angle: float) -> float:
    """The ball-minus-figurine y offset whose kick sends the ball at ``angle`` (rad)."""
    degrees = min(abs(math.degrees(angle)), float(_ANGLES[-1]))
    offset = float(np.interp(degrees, _ANGLES, _OFFSETS))
    if degrees < 1e-6:
        return 0.0
    return math.copysign(offset, angle)


def path_y(x0: float, y0: float, angle: float, xs: Sequence[float]) -> list[float]:
    """Where a ball leaving (x0, y0) at ``angle`` crosses each x in ``xs`` (increasing, all
    beyond x0), bouncing off the side walls, which halve its sideways speed."""
    slope = math.tan(angle)
    x, y, out = x0, y0, []
    for target in xs:
        while True:
            reach = y + slope * (target - x)
            if abs(reach) <= _WALL or slope == 0:
                out.append(reach)
                x, y = target, reach
                break
            wall = math.copysign(_WALL, slope)
            x += (wall - y) / slope
            y = wall
            slope = -slope * _WALL_RESTITUTION
    return out


def clearance(
    x0: float, y0: float, angle: float, blockers: Sequence[tuple[float, Sequence[float]]]
) -> float:
    """The smallest margin (m) by which a shot at ``angle`` passes every blocking figurine
    and stays inside the goal mouth; negative when it is blocked or misses."""
    ahead = sorted((bx, fys) for bx, fys in blockers if bx > x0)
    xs = [bx for bx, _ in ahead] + [table.GOAL_LINE_X]
    ys = path_y(x0, y0, angle, xs)

    margin = _GOAL - abs(ys[-1])
    for (_, fys), y in zip(ahead, ys):
        for fy in fys:
            margin = min(margin, abs(y - fy) - _BLOCK)
    # A path that overflowed (see _clearances) passes nothing.
    return -math.inf if math.isnan(margin) else margin


def plan_shot(
    x0: float,
    y0: float,
    blockers: Sequence[tuple[float, Sequence[float]]],
    steps: int = 55,
) -> float:
    """The shot angle (rad) whose worst clearance over its likely error is widest.

    Corner kicks come out several degrees off, more at wider angles, so an angle is judged by
    the worst of itself and its neighbours within an allowed error that grows with the angle;
    straighter shots win ties.
    A straight shot with an open lane is taken as it is: it is the fastest and surest.
    """
    if clearance(x0, y0, 0.0, blockers) > 0.0:
        return 0.0
    angles = np.linspace(-MAX_ANGLE, MAX_ANGLE, 2 * steps + 1)
    # The flat face ends abruptly at the corner: kicks at these angles come out straight.
    angles = angles[~((np.abs(angles) > 0.0) & (np.abs(angles) < MIN_ANGLE))]
    error = ANGLE_ERROR + ANGLE_ERROR_SLOPE * np.abs(angles)
    judged = np.concatenate([angles - error, angles, angles + error])
    score = _clearances(x0, y0, judged, blockers).reshape(3, -1).min(axis=0)
    score = np.minimum(score, CLEAR_ENOUGH) - 0.01 * np.abs(angles)
    return float(angles[int(np.argmax(score))])


def _clearances(
    x0: float, y0: float, angles: np.ndarray, blockers: Sequence[tuple[float, Sequence[float]]]
) -> np.ndarray:
    """:func:`clearance` for many angles at once, to the last bit: the same operations in the
    same order, with the slopes from :func:`math.tan` as :func:`path_y` takes them."""
    ahead = sorted((bx, fys) for bx, fys in blockers if bx > x0)
    xs = [bx for bx, _ in ahead] + [table.GOAL_LINE_X]
    slope = np.array([math.tan(a) for a in angles.tolist()])
    x = np.full_like(slope, x0)
    y = np.full_like(slope, y0)
    ys = []
    # A ball a little beyond the walls' line (pressed into a wall) shot at a flat angle away
    # from it bounces on for ever, ever further behind: the path overflows, as Python's
    # floats do in clearance(), and its margin is NaN, which counts as blocked below.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        for target in xs:
            while True:
                reach = y + slope * (target - x)
                over = (np.abs(reach) > _WALL) & (slope != 0)
                if not over.any():
                    break
                wall = np.copysign(_WALL, slope[over])
                x[over] += (wall - y[over]) / slope[over]
                y[over] = wall
                slope[over] = -slope[over] * _WALL_RESTITUTION
            ys.append(reach)
            x = np.full_like(slope, target)
            y = reach.copy()
    margin = _GOAL - np.abs(ys[-1])
    for (_, fys), y in zip(ahead, ys):
        for fy in fys:
            margin = np.minimum(margin, np.abs(y - fy) - _BLOCK)
    # A NaN would be the largest margin to argmax, and the shot chosen.
    return np.where(np.isnan(margin), -np.inf, margin)
