"""The simulated table: the only code that imports pybullet.

:class:`TableSim` (``table_sim``) runs a table in control steps. Beside it, by job: the rods'
drives as plain arithmetic (``drives``), where the ball and the figurines can get to within a
step (``contacts``), the Bullet worlds (``worlds``; the one module that imports pybullet), the
URDF with the rods in play (``urdf``) and the table as it is drawn (``view``).
"""

from foosball_gym.sim.drives import CONTROL_MODES, drive_acceleration
from foosball_gym.sim.table_sim import (
    AWAY_SCORED,
    HOME_SCORED,
    NO_GOAL,
    BallState,
    TableSim,
    figurine_centres,
)
from foosball_gym.sim.view import View

__all__ = [
    "AWAY_SCORED",
    "CONTROL_MODES",
    "HOME_SCORED",
    "NO_GOAL",
    "BallState",
    "TableSim",
    "View",
    "drive_acceleration",
    "figurine_centres",
]
