"""The object dictionary of a CiA 402 position drive, as far as this package uses it.

The master addresses a drive through it, and each simulated drive is a ``canopen.LocalNode``
built on it.
"""

from __future__ import annotations

from canopen.objectdictionary import (
    INTEGER8,
    INTEGER16,
    INTEGER32,
    UNSIGNED8,
    UNSIGNED16,
    UNSIGNED32,
    ObjectDictionary,
    ODRecord,
    ODVariable,
)

from foosball_gym.real_table.hardware.cia402.protocol import (
    ABORT_CONNECTION_OPTION_CODE,
    COMMUNICATION_CYCLE_PERIOD,
    CONSUMER_HEARTBEAT_TIME,
    CONTROLWORD,
    DEVICE_PROFILE,
    DEVICE_TYPE,
    DISABLE_OPERATION_OPTION_CODE,
    ERROR_REGISTER,
    FAULT_REACTION_OPTION_CODE,
    INTERPOLATION_TIME_PERIOD,
    MODE_CODES,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    POSITION_ACTUAL,
    PRODUCER_HEARTBEAT_TIME,
    PROFILE_ACCELERATION,
    PROFILE_DECELERATION,
    PROFILE_VELOCITY,
    QUICK_STOP_DECELERATION,
    QUICK_STOP_OPTION_CODE,
    SHUTDOWN_OPTION_CODE,
    STATUSWORD,
    SUPPORTED_DRIVE_MODES,
    TARGET_POSITION,
    VELOCITY_ACTUAL,
)

CONSUMER_HEARTBEAT_ENTRIES = 4


def _variable(
    name: str, index: int, subindex: int, data_type: int, access: str = "rw", default: int = 0
) -> ODVariable:
    var = ODVariable(name, index, subindex)
    var.data_type = data_type
    var.access_type = access
    var.default = default
    return var


def object_dictionary(node_id: int) -> ObjectDictionary:
    """The objects of a CiA 402 position drive this package uses, for one node.

    Enough for a master to address a real C5-E and for a ``canopen.LocalNode`` to play one:
    device type, error register, cycle period, producer and consumer heartbeat, 4 RPDOs and 4
    TPDOs (all disabled and empty, as after a reset to factory settings), the stop reactions
    (option codes) and the drive objects of both modes.
    """
    od = ObjectDictionary()
    od.node_id = node_id
    for var in (
        # Bits 16-23 = 2: a servo drive.
        _variable("Device type", DEVICE_TYPE, 0, UNSIGNED32, "ro", (2 << 16) | DEVICE_PROFILE),
        _variable("Error register", ERROR_REGISTER, 0, UNSIGNED8, "ro"),
        _variable("Communication cycle period", COMMUNICATION_CYCLE_PERIOD, 0, UNSIGNED32),
        _variable("Producer heartbeat time", PRODUCER_HEARTBEAT_TIME, 0, UNSIGNED16),
        _variable("Controlword", CONTROLWORD, 0, UNSIGNED16),
        _variable("Statusword", STATUSWORD, 0, UNSIGNED16, "ro"),
        _variable(
            "Abort connection option code", ABORT_CONNECTION_OPTION_CODE, 0, INTEGER16, default=1
        ),
        _variable("Quick stop option code", QUICK_STOP_OPTION_CODE, 0, INTEGER16, default=2),
        _variable("Shutdown option code", SHUTDOWN_OPTION_CODE, 0, INTEGER16),
        _variable(
            "Disable operation option code", DISABLE_OPERATION_OPTION_CODE, 0, INTEGER16, default=1
        ),
        _variable(
            "Fault reaction option code", FAULT_REACTION_OPTION_CODE, 0, INTEGER16, default=2
        ),
        _variable("Modes of operation", MODES_OF_OPERATION, 0, INTEGER8),
        _variable("Modes of operation display", MODES_OF_OPERATION_DISPLAY, 0, INTEGER8, "ro"),
        _variable("Position actual value", POSITION_ACTUAL, 0, INTEGER32, "ro"),
        _variable("Velocity actual value", VELOCITY_ACTUAL, 0, INTEGER32, "ro"),
        _variable("Target position", TARGET_POSITION, 0, INTEGER32),
        _variable("Profile velocity", PROFILE_VELOCITY, 0, UNSIGNED32),
        _variable("Profile acceleration", PROFILE_ACCELERATION, 0, UNSIGNED32),
        _variable("Profile deceleration", PROFILE_DECELERATION, 0, UNSIGNED32),
        _variable("Quick stop deceleration", QUICK_STOP_DECELERATION, 0, UNSIGNED32),
        _variable(
            "Supported drive modes",
            SUPPORTED_DRIVE_MODES,
            0,
            UNSIGNED32,
            "ro",
            sum(1 << (code - 1) for code in MODE_CODES.values()),
        ),
    ):
        od.add_object(var)
    index = CONSUMER_HEARTBEAT_TIME
    consumers = ODRecord("Consumer heartbeat time", index)
    consumers.add_member(
        _variable("Highest sub-index", index, 0, UNSIGNED8, "const", CONSUMER_HEARTBEAT_ENTRIES)
    )
    for sub in range(1, CONSUMER_HEARTBEAT_ENTRIES + 1):
        # Bits 16-23: the node id watched; bits 0-15: its heartbeat timeout in ms (0: off).
        consumers.add_member(_variable(f"Consumer heartbeat {sub}", index, sub, UNSIGNED32))
    od.add_object(consumers)
    index = INTERPOLATION_TIME_PERIOD
    interpolation = ODRecord("Interpolation time period", index)
    interpolation.add_member(_variable("Highest sub-index", index, 0, UNSIGNED8, "const", 2))
    interpolation.add_member(_variable("Time period units", index, 1, UNSIGNED8))
    interpolation.add_member(_variable("Time period index", index, 2, INTEGER8, default=-3))
    od.add_object(interpolation)
    pdos = (("RPDO", 0x1400, 0x1600, 0x200), ("TPDO", 0x1800, 0x1A00, 0x180))
    for n in range(4):
        for kind, com, mapping, cob_base in pdos:
            index = com + n
            record = ODRecord(f"{kind}{n + 1} communication parameter", index)
            subs = 5 if kind == "TPDO" else 2
            record.add_member(_variable("Highest sub-index", index, 0, UNSIGNED8, "const", subs))
            cob_id = (1 << 31) | (cob_base + 0x100 * n + node_id)  # bit 31: not valid
            record.add_member(_variable("COB-ID", index, 1, UNSIGNED32, default=cob_id))
            record.add_member(_variable("Transmission type", index, 2, UNSIGNED8, default=255))
            if kind == "TPDO":
                record.add_member(_variable("Inhibit time", index, 3, UNSIGNED16))
                record.add_member(_variable("Event timer", index, 5, UNSIGNED16))
            od.add_object(record)
            index = mapping + n
            record = ODRecord(f"{kind}{n + 1} mapping parameter", index)
            record.add_member(_variable("Number of mapped objects", index, 0, UNSIGNED8))
            for sub in range(1, 9):
                record.add_member(_variable(f"Mapped object {sub}", index, sub, UNSIGNED32))
            od.add_object(record)
    return od
