"""Aimed deflections: where to hold a still figurine so that a ball rolling into it leaves for
the goal.

A fast ball that meets a still, upright figurine bounces off it. Off the flat front the ball
leaves at the mirror angle (steeper: only half its normal speed comes back); off a rounded end
it leaves at an angle that turns by about 10 degrees per millimetre of sideways offset. So the
offset between the ball's crossing point and the figurine picks the direction, and with the
feet held still that direction depends on nothing but the ball's path: no swing has to be
timed to a ball that moves 8 cm in one decision (1/60 s), which is what makes a volley miss.

The table holds that direction, measured in the simulator (``sim.probes.deflection``,
``scripts/deflection_table.py``, physics revision in the file) over the ball's speed 0.55 m
before the rod, its angle from -x and the offset; for a ball moving towards -y the picture is
mirrored.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from foosball_gym.policies import measured

TABLE_PATH = Path(__file__).with_name("deflection_table.npz")
SPEEDS = np.arange(2.5, 7.51, 0.5)  # m/s
ANGLES = np.arange(0.0, 42.51, 1.25)  # degrees from -x, ball moving towards +y
OFFSETS = np.round(np.arange(-0.02, 0.02001, 0.00025), 6)  # ball minus figurine y, m
# Neighbouring offsets whose directions differ by more than this (degrees) straddle the edge
# of the foot or a jump between contact facets: no aim is read across them.
_JUMP = 15.0
_FLAT = int(np.argmin(np.abs(OFFSETS)))  # the offset 0: the middle of the flat face


def _table() -> tuple[np.ndarray, int]:
    return measured.load(TABLE_PATH)


def table_revision() -> int:
    """The physics revision the shipped table was measured on."""
    return _table()[1]


def _offset_on(directions: np.ndarray, target: float) -> float | None:
    """The offset nearest the flat face at which one measured row of directions passes
    ``target`` (degrees), read linearly between neighbouring offsets."""
    best = None
    for step in (-1, 1):
        k = _FLAT
        while 0 <= k + step < len(OFFSETS):
            a, b = float(directions[k]), float(directions[k + step])
            if math.isnan(a) or math.isnan(b) or abs(b - a) > _JUMP:
                break
            if (a - target) * (b - target) <= 0 and a != b:
                found = OFFSETS[k] + (a - target) / (a - b) * (OFFSETS[k + step] - OFFSETS[k])
                if best is None or abs(found) < abs(best):
                    best = float(found)
                break
            k += step
    return best


def _directions(speed: float, angle_deg: float) -> np.ndarray:
    """Direction (degrees from +x) per offset, interpolated between the measured speeds and
    angles."""
    out = _table()[0]
    i, fs = _cell(SPEEDS, speed)
    j, fa = _cell(ANGLES, angle_deg)
    near = (1 - fa) * out[i, j] + fa * out[i, j + 1]
    far = (1 - fa) * out[i + 1, j] + fa * out[i + 1, j + 1]
    return (1 - fs) * near + fs * far


def _cell(axis: np.ndarray, value: float) -> tuple[int, float]:
    value = float(np.clip(value, axis[0], axis[-1]))
    i = min(int(np.searchsorted(axis, value, side="right")) - 1, len(axis) - 2)
    return i, (value - axis[i]) / (axis[i + 1] - axis[i])


def deflection_offset(speed: float, angle: float, want: float) -> float | None:
    """The ball-minus-figurine y offset (m) that sends a ball arriving at ``speed`` (m/s) and
    ``angle`` (rad from -x, positive towards +y) off at ``want`` (rad from +x); None where no
    offset within reach of the foot's flat does.

    Of the offsets on either side of the flat face, the smaller one: the nearer a rounded end
    is struck to the flat, the less its direction changes with a small error. Between the
    measured angles the direction is not smooth (the contact moves across facets of the
    figurine's hull: about 3 degrees within one 1.25-degree step), so an aim between them is
    good to a few degrees, and the goal mouth's +-4 degrees from the keeper leave room for it.
    """
    sign = 1.0 if angle >= 0 else -1.0
    found = _offset_on(_directions(speed, abs(math.degrees(angle))), sign * math.degrees(want))
    return None if found is None else sign * found
