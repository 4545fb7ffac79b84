"""The calibration serves: a pattern of balls that shows a table's physics to a fit.

``foosball play MODEL --table sim --serves calibration`` serves these instead of the task's own
balls (:class:`~foosball_gym.real_table.virtual.simulated_table.SimulatedTable`), and a person does
much the same by hand on a real table (docs/system-identification.md). Each ball is put in a
part of the table no figurine can reach, at 0.6-2.5 m/s across the table or along it, and left
to run for up to :data:`CALIBRATION_SERVE_S`:

- rolling balls, which show the rolling resistance over the seconds they take to slow down;
- side and end wall bounces, which show the restitution;
- balls that start sliding (a third of them, and every ball after a bounce until its spin
  catches up), which show the ball's friction on the cloth;
- balls that run at the policy's rods, which make the drives step and the figurines meet the
  ball.

Nothing here needs the simulator.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from foosball_gym import table

#: The serve patterns of the simulated table: the task's own balls, or the calibration serves.
SERVE_PATTERNS = ("task", "calibration")
#: The longest a calibration serve lasts (s); a goal, a ball off the table or a dead ball end it
#: sooner.
CALIBRATION_SERVE_S = 4.0
#: The speeds calibration balls start at (m/s): slow enough to roll for seconds, fast enough to
#: bounce off a wall or two.
CALIBRATION_SPEEDS = (0.6, 2.5)
#: Half the calibration balls run across the table, at most this many degrees off the side
#: walls' normal, and half along it, at most ALONG_ANGLE degrees off its length.
CROSSING_ANGLE = 60.0
ALONG_ANGLE = 30.0
#: The share of calibration balls that start rolling; the others start sliding without spin.
ROLLING_SHARE = 2 / 3
#: How far along x from a rod's axis the ball's centre must be for no figurine of the rod to
#: touch it, whatever the rod does: a swinging foot's reach, and a margin for the ball's travel
#: while the camera looks away.
ROD_CLEARANCE = table.FOOT_REACH_X + 0.015
# Calibration balls start this far from the end walls and the side walls.
_END_MARGIN = 0.06
_SIDE_MARGIN = 0.04


@dataclass(frozen=True)
class CalibrationServe:
    """One calibration ball: where it starts, its velocity, and whether it starts rolling
    (otherwise sliding without spin)."""

    position: tuple[float, float]
    velocity: tuple[float, float]
    rolling: bool


def free_bands(rods: Sequence[str]) -> list[tuple[float, float]]:
    """The stretches of x along the field where no figurine of ``rods`` reaches the ball, from
    the home end to the away end (the two outer ones open-ended)."""
    edges = sorted(table.rod(name).x for name in rods)
    # The end walls bound the field: a measurement a hair beyond one is still on it.
    bands, low = [], -math.inf
    for x in edges:
        if x - ROD_CLEARANCE > low:
            bands.append((low, x - ROD_CLEARANCE))
        low = max(low, x + ROD_CLEARANCE)
    bands.append((low, math.inf))
    return bands


def calibration_serve(rng: np.random.Generator, rods: Sequence[str]) -> CalibrationServe:
    """A calibration ball for a table with ``rods`` in play, drawn from ``rng``.

    It starts in the widest stretches of the field no figurine reaches (drawn in proportion to
    their length); a table whose rods leave no such stretch gets the ball in the middle of the
    field.
    """
    inner = table.BALL_LIMIT_X - _END_MARGIN
    bands = [(max(lo, -inner), min(hi, inner)) for lo, hi in free_bands(rods)]
    bands = [(lo, hi) for lo, hi in bands if hi > lo]
    if bands:
        lengths = np.array([hi - lo for lo, hi in bands])
        lo, hi = bands[int(rng.choice(len(bands), p=lengths / lengths.sum()))]
        x = float(rng.uniform(lo, hi))
    else:
        x = 0.0
    y = float(rng.uniform(-1, 1)) * (table.BALL_LIMIT_Y - _SIDE_MARGIN)
    # Half across the table, within CROSSING_ANGLE of the side walls' normal: they meet the
    # side walls. Half along it, within ALONG_ANGLE of its length: they run longest between
    # walls, and meet the rods or an end wall.
    if rng.random() < 0.5:
        spread, axis = CROSSING_ANGLE, math.pi / 2
    else:
        spread, axis = ALONG_ANGLE, 0.0
    angle = math.radians(float(rng.uniform(-spread, spread))) + axis
    angle += math.pi if rng.random() < 0.5 else 0.0
    speed = float(rng.uniform(*CALIBRATION_SPEEDS))
    rolling = bool(rng.random() < ROLLING_SHARE)
    velocity = (speed * math.cos(angle), speed * math.sin(angle))
    return CalibrationServe((x, y), velocity, rolling)


def check_serves(value: object) -> str:
    """A serve pattern's name, or a ValueError naming those there are."""
    if value not in SERVE_PATTERNS:
        raise ValueError(f"unknown serve pattern {value!r}; allowed: {', '.join(SERVE_PATTERNS)}")
    return str(value)
