"""CiA 402 drives on CANopen, from the master's side.

- :mod:`~foosball_gym.real_table.hardware.cia402.protocol`: object indices, controlword and
  statusword bits, mode and option codes, and the state a statusword shows.
- :mod:`~foosball_gym.real_table.hardware.cia402.object_dictionary`: the objects of a drive.
- :mod:`~foosball_gym.real_table.hardware.cia402.bring_up`: what bring-up writes so a drive stops
  safely on its own, and the mode's settings and PDOs.
- :mod:`~foosball_gym.real_table.hardware.cia402.drive`: :class:`Cia402Drive`, one drive.
"""

from __future__ import annotations

from foosball_gym.real_table.hardware.cia402.drive import Cia402Drive
from foosball_gym.real_table.hardware.cia402.object_dictionary import object_dictionary
from foosball_gym.real_table.hardware.cia402.protocol import state_name

__all__ = ["Cia402Drive", "object_dictionary", "state_name"]
