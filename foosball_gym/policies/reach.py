"""How far a defending figurine can get in a given time: what decides whether a shot can be
blocked by a rod that only starts to move when it sees the ball coming.

A rod's slide drive asks for a speed proportional to what is left to go (its position gain),
within its top speed, and gets there as fast as its force can accelerate what it moves
(:mod:`foosball_gym.sim.drives`). A figurine blocks a ball whose centre passes within
:data:`BLOCK` of its own; so to block a ball crossing its line ``d`` away it has to close
``d - BLOCK`` with the target ``d`` away. :func:`cover_distance` tabulates that once per rod,
driving the same law as the simulator (:mod:`foosball_gym.sim.drives`, which policies do
not import), from rest.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from foosball_gym import table

# A figurine stops a ball whose centre passes within its leg's half width plus the ball's
# radius of its own centre.
BLOCK = table.FIGURINE_LEG_HALF_WIDTH + table.BALL_RADIUS
# The slide drives' position gain in the simulator (1/s; TableSim's slide_gain).
SLIDE_GAIN = 48.0
# A defender sees a shot one control step after it is struck at the latest, and its drive
# follows the next command from then on.
REACTION = 1.0 / table.CONTROL_HZ
_DT = 1.0 / 960
_DISTANCES = np.linspace(0.0, 0.7, 141)


@cache
def _cover_times(role: str) -> np.ndarray:
    """Seconds a figurine of ``role`` needs, from rest, to come within BLOCK of a point each of
    :data:`_DISTANCES` away."""
    rod = table.rod(f"{table.HOME}_{role}")
    # What the drive moves: as foosball_gym.sim.drives.drive_acceleration has it.
    moving = table.CARRIAGE_MASS + table.ROD_MASS + len(rod.figurine_offsets) * table.FIGURINE_MASS
    accel = table.SLIDE_MAX_FORCE / moving
    times = []
    for target in _DISTANCES:
        q = v = t = 0.0
        while q < target - BLOCK:
            v = min(table.SLIDE_MAX_SPEED, SLIDE_GAIN * (target - q), v + accel * _DT)
            q += v * _DT
            t += _DT
        times.append(t)
    return np.array(times)


def cover_time(role: str, distance: float) -> float:
    """Seconds a resting figurine of a ``role`` rod needs to block a ball crossing its line
    ``distance`` (m) from it, reaction not included."""
    return float(np.interp(abs(distance), _DISTANCES, _cover_times(role)))


def move_distance(role: str, seconds: float) -> float:
    """How far a resting figurine of a ``role`` rod can go to block a ball that crosses its
    line ``seconds`` after the strike, the defender's reaction included: with BLOCK either
    side of where it gets to, what it covers."""
    left = seconds - REACTION
    if left <= 0.0:
        return 0.0
    return max(0.0, float(np.interp(left, _cover_times(role), _DISTANCES)) - BLOCK)


def move_distances(role: str, seconds: np.ndarray) -> np.ndarray:
    """:func:`move_distance` for many times at once."""
    left = np.asarray(seconds, dtype=float) - REACTION
    moved = np.interp(left, _cover_times(role), _DISTANCES) - BLOCK
    return np.where(left > 0.0, np.maximum(moved, 0.0), 0.0)
