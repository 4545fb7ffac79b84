"""The simulated table: the only code that imports pybullet.

:class:`TableSim` (``table_sim``) runs a table in control steps. Beside it, by job: the rods'
drives as plain arithmetic (``drives``), where the ball and the figurines can get to within a
step (``contacts``), the Bullet worlds (``worlds``; the one module that imports pybullet), the
URDF with the rods in play (``urdf``), the table as it is drawn (``view``), the physics options
and their checks (``options``) and the probes that measure the contacts (``probes``).

The package imports a module when one of its names is first asked for: checking the physics
options (``foosball_gym.sim.options``) must not load pybullet, which a machine that only drives
the real table may not have.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
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

#: Each name the package offers, with the module that holds it.
_HOME = {
    "AWAY_SCORED": "table_sim",
    "CONTROL_MODES": "drives",
    "HOME_SCORED": "table_sim",
    "NO_GOAL": "table_sim",
    "BallState": "table_sim",
    "TableSim": "table_sim",
    "View": "view",
    "drive_acceleration": "drives",
    "figurine_centres": "table_sim",
}

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


def __getattr__(name: str) -> Any:
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{home}"), name)
    globals()[name] = value  # asked once: the next lookup finds it without this function
    return value
