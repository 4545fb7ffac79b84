"""Aimed volleys: where to hold a swinging figurine so that an incoming ball it strikes leaves
for the goal.

A volley (the keeper's feet wound up behind the rod, swung through as the ball arrives) struck
with the flat face of the foot sends the ball off at a direction set by the ball's incoming
angle and speed, whether or not that is at the goal. Struck with a rounded end, the direction
turns with the sideways offset (10-20 degrees per 4 mm), but there it also depends, by tens of
degrees, on where within a control step (1/60 s, 8 cm of travel at 5 m/s) the swing meets the
ball, where off the flat face it moves by a few. So an offset is chosen not by the direction it
gives on average but by how often it scores: of the swings measured at different points of a
control step, the share whose path, side-wall bounces included, reaches the goal line inside
the mouth (less a margin). That share is smoothed over neighbouring offsets, since the
crossing point a camera and a filter give is a few millimetres off, and an offset is used
only where it beats the flat face's.

The table holds the directions, measured in the simulator (``sim.probes.volley``,
``scripts/volley_table.py``, physics revision in the file) over the ball's speed, its angle
from -x (positive towards +y), the ball-minus-figurine offset and the phase of the ball's
start within a control step. A ball is read at the nearest measured speed and angle.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from foosball_gym import table
from foosball_gym.policies import measured
from foosball_gym.policies.aiming import path_y

TABLE_PATH = Path(__file__).with_name("volley_table.npz")
SPEEDS = np.arange(2.5, 8.51, 1.0)  # m/s
# Degrees from -x, positive towards +y. At +-35 the probe's ball would start beyond a side
# wall: those cells hold no swing, and a ball read there is volleyed with the flat face.
ANGLES = np.arange(-35.0, 35.01, 5.0)
OFFSETS = np.round(np.arange(-0.02, 0.02001, 0.002), 6)  # ball minus figurine y, m
PHASES = (0.0, 0.25, 0.5, 0.75)  # the ball's start moved back by this share of a step's travel
# A volley that scores only just inside a post scores less often through a camera.
MARGIN = 0.02  # m
# Neighbouring offsets (each side) a share is averaged over: the estimated crossing point is a
# few millimetres off, so an offset scores as well as its neighbours do.
SMOOTH = 1
# How much more often than the flat face an offset must score to be used, and how much a
# millimetre of offset costs among offsets that score about as often.
_BETTER = 0.01
_PER_MM = 0.001
# A ball struck further round than this is going sideways, not at any goal.
_SIDEWAYS = 75.0  # degrees
_FLAT = int(np.argmin(np.abs(OFFSETS)))


def _table() -> tuple[np.ndarray, int]:
    return measured.load(TABLE_PATH)


def table_revision() -> int:
    """The physics revision the shipped table was measured on."""
    return _table()[1]


def _check(cross: float, slope: float, speed: float) -> None:
    if not abs(cross) <= table.BALL_LIMIT_Y:
        raise ValueError(
            f"the crossing point must lie on the table, |y| <= {table.BALL_LIMIT_Y} m; got {cross}"
        )
    if not math.isfinite(slope):
        raise ValueError(f"the ball's slope must be a finite number, got {slope}")
    if not speed > 0 or not math.isfinite(speed):
        raise ValueError(f"the ball's speed must be a positive number of m/s, got {speed}")


def goal_shares(cross: float, slope: float, speed: float, rod_x: float) -> np.ndarray:
    """Per offset in ``OFFSETS``: the share of measured swings that score a ball crossing the
    line of a rod at x = ``rod_x`` at y = ``cross`` on a path of ``slope`` (dy/|dx|, positive
    towards +y) at ``speed`` (m/s), averaged over ``SMOOTH`` neighbouring offsets each side.

    Raises:
        ValueError: a crossing point off the table, or a speed or slope that is not a
            positive or finite number.
    """
    _check(cross, slope, speed)
    i = int(np.argmin(np.abs(SPEEDS - speed)))
    j = int(np.argmin(np.abs(ANGLES - math.degrees(math.atan(slope)))))
    directions = _table()[0][i, j]  # offsets x phases, degrees from +x
    mouth = table.GOAL_HALF_WIDTH - MARGIN
    scores = np.zeros(directions.shape)
    for k, row in enumerate(directions):
        for p, out_deg in enumerate(row.tolist()):
            if math.isnan(out_deg) or abs(out_deg) > _SIDEWAYS:
                continue
            end = path_y(rod_x, cross, math.radians(out_deg), [table.GOAL_LINE_X])[-1]
            scores[k, p] = abs(end) < mouth
    share = scores.mean(axis=1)
    if SMOOTH:
        padded = np.pad(share, SMOOTH, mode="edge")
        share = np.convolve(padded, np.ones(2 * SMOOTH + 1) / (2 * SMOOTH + 1), mode="valid")
    return share


def volley_offset(cross: float, slope: float, speed: float, rod_x: float) -> float:
    """The ball-minus-figurine y offset (m) to volley a ball with, as :func:`goal_shares`
    takes it: the one that scores most often, the smaller one where two score about as often,
    and 0 (the flat face) unless another scores more often by more than 1 %.

    Raises:
        ValueError: as :func:`goal_shares`.
    """
    share = goal_shares(cross, slope, speed, rod_x)
    best = int(np.argmax(share - _PER_MM * np.abs(OFFSETS) * 1000))
    if share[best] > share[_FLAT] + _BETTER:
        return float(OFFSETS[best])
    return 0.0
