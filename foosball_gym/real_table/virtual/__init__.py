"""A simulated real table, for ``foosball play --table sim``: what the real-table stack meets.

Not the simulator (:mod:`foosball_gym.sim`) but what stands where the real table would: CiA 402
drives on python-can's virtual CAN bus that move a ``TableSim``'s rods, a camera rendering it
in a process of its own, and a window to watch and play it in. The only hardware-side package
that uses the simulator.
"""

from __future__ import annotations

from foosball_gym.real_table.virtual.drive import SimulatedDrive
from foosball_gym.real_table.virtual.drives import SimulatedDrives

__all__ = ["SimulatedDrive", "SimulatedDrives"]
