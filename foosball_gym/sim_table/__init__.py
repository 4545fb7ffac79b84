"""The simulated table seen as hardware: drives on a virtual CAN bus that move a ``TableSim``.

The only hardware-side package that uses the simulator.
"""

from __future__ import annotations

from foosball_gym.sim_table.drives import SimulatedDrive, SimulatedDrives

__all__ = ["SimulatedDrive", "SimulatedDrives"]
