"""The numbers of CiA 301 and CiA 402 this package uses, and the state a statusword shows.

Object indices, controlword commands, statusword bits, the codes of the modes of operation and
of the stop reactions (option codes), as the master and the simulated drives both read them.
"""

from __future__ import annotations

from canopen.profiles.p402 import State402

# Objects (CiA 301 communication, CiA 402 drive profile).
DEVICE_TYPE = 0x1000
ERROR_REGISTER = 0x1001
COMMUNICATION_CYCLE_PERIOD = 0x1006
CONSUMER_HEARTBEAT_TIME = 0x1016
PRODUCER_HEARTBEAT_TIME = 0x1017
ABORT_CONNECTION_OPTION_CODE = 0x6007
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
QUICK_STOP_OPTION_CODE = 0x605A
SHUTDOWN_OPTION_CODE = 0x605B
DISABLE_OPERATION_OPTION_CODE = 0x605C
FAULT_REACTION_OPTION_CODE = 0x605E
MODES_OF_OPERATION = 0x6060
MODES_OF_OPERATION_DISPLAY = 0x6061
POSITION_ACTUAL = 0x6064
VELOCITY_ACTUAL = 0x606C
TARGET_POSITION = 0x607A
PROFILE_VELOCITY = 0x6081
PROFILE_ACCELERATION = 0x6083
PROFILE_DECELERATION = 0x6084
QUICK_STOP_DECELERATION = 0x6085
INTERPOLATION_TIME_PERIOD = 0x60C2
SUPPORTED_DRIVE_MODES = 0x6502

# Controlword commands and bits.
CW_DISABLE_VOLTAGE = State402.CW_DISABLE_VOLTAGE  # 0x00
CW_QUICK_STOP = State402.CW_QUICK_STOP  # 0x02
CW_SHUTDOWN = State402.CW_SHUTDOWN  # 0x06
CW_SWITCH_ON = State402.CW_SWITCH_ON  # 0x07
CW_ENABLE_OPERATION = State402.CW_OPERATION_ENABLED  # 0x0F
CW_FAULT_RESET = 0x80
CW_NEW_SET_POINT = 0x10  # pp: a rising edge hands the target position to the drive
CW_CHANGE_IMMEDIATELY = 0x20  # pp: the new target replaces the current one at once

# Statusword bits.
SW_FAULT = 0x0008
SW_TARGET_REACHED = 0x0400  # in QUICK STOP ACTIVE: the drive has halted
SW_SET_POINT_ACKNOWLEDGE = 0x1000  # pp

MODE_CODES = {"pp": 1, "csp": 8}
DEVICE_PROFILE = 402
# 0x605A = 2: slow down on the quick stop ramp, then switch the power stage off (SWITCH ON
# DISABLED). A drive that stopped itself, its master gone or hung, ends unpowered, not
# holding under power with nobody left to switch it off.
QUICK_STOP_THEN_SWITCH_OFF = 2
# 0x605B, 0x605C = 1: slow down on the slow-down ramp, then switch the power stage off.
SLOW_DOWN_THEN_DISABLE = 1
# 0x605E = 2: the fault reaction brakes on the quick stop ramp.
FAULT_REACTION_QUICK_STOP = 2
# 0x6007 = 3: a lost connection to the master (its heartbeat) quick-stops the drive.
ABORT_CONNECTION_QUICK_STOP = 3

OPERATION_ENABLED = "OPERATION ENABLED"
# The states in which the power stage drives the motor.
POWERED_STATES = (OPERATION_ENABLED, "QUICK STOP ACTIVE", "FAULT REACTION ACTIVE")
NMT_OPERATIONAL = 5
NMT_BOOT_UP = 0

_STATE_MASKS = tuple(State402.SW_MASK.items())


def state_name(statusword: int) -> str:
    """The CiA 402 state a statusword shows (``"OPERATION ENABLED"``, ``"FAULT"``, ...)."""
    for name, (mask, value) in _STATE_MASKS:
        if statusword & mask == value:
            return name
    return "UNKNOWN"
