"""The two-player games' full true state: what PettingZoo's ``state()`` gives a centralised
critic.

Every joint of the rods in play and the ball in three dimensions, in the world (home) frame, as
the simulator has them: the same whatever the observation options, and more than either agent
observes (the ball's height and vertical speed, the spins of rods an agent sees only slide).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
from gymnasium import spaces

if TYPE_CHECKING:
    from foosball_gym.sim import BallState

# Generous bounds, as the observations' (a Box needs some; the values never come near them).
POSITION_BOUND = 10.0  # m, rad
VELOCITY_BOUND = 400.0  # m/s, rad/s: Bullet holds a spin below 1.1 x 100 pi rad/s


class TrueState:
    """The state vector of a table with ``rods`` in play.

    Its entries, in order: each rod's slide and spin position (``home_keeper_slide_pos``,
    ``home_keeper_spin_pos``, ...), the same velocities (``..._vel``), then ``ball_x``,
    ``ball_y``, ``ball_z``, ``ball_vx``, ``ball_vy``, ``ball_vz``.

    Args:
        rods: the rods in play, in the order of the simulator's joints.
    """

    def __init__(self, rods: Sequence[str]) -> None:
        n = len(rods)
        joints = [f"{rod}_{joint}" for rod in rods for joint in ("slide", "spin")]
        ball = ("ball_x", "ball_y", "ball_z", "ball_vx", "ball_vy", "ball_vz")
        self.names: tuple[str, ...] = (
            *(f"{j}_pos" for j in joints),
            *(f"{j}_vel" for j in joints),
            *ball,
        )
        # The simulator's joints are all slides, then all spins; the state goes rod by rod.
        self._order = [j for i in range(n) for j in (i, n + i)]
        bound = [POSITION_BOUND] * 2 * n + [VELOCITY_BOUND] * 2 * n
        bound += [POSITION_BOUND] * 3 + [VELOCITY_BOUND] * 3
        high = np.array(bound, dtype=np.float32)
        self.space = spaces.Box(-high, high, dtype=np.float32)

    def build(
        self, positions: Sequence[float], velocities: Sequence[float], ball: BallState
    ) -> np.ndarray:
        """The state vector from the joints (all slides, then all spins) and the ball."""
        order = self._order
        return np.array(
            [
                *(positions[j] for j in order),
                *(velocities[j] for j in order),
                *ball.position,
                *ball.velocity,
            ],
            dtype=np.float32,
        )
