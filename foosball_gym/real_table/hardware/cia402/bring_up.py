"""What bring-up writes into a drive, so that it stops safely on its own and runs its mode.

The heartbeats, stop reactions and ramps (CiA 301 / CiA 402):

- 0x1017 producer heartbeat time: the drive beats three times per heartbeat timeout, so the
  master notices a dead drive.
- 0x1016 consumer heartbeat time, sub-index 1: the master's node id and the heartbeat timeout.
  The master beats from a thread of its own (``TableDrives``); a master that is killed, hangs
  with the interpreter stuck, or loses the bus stops beating, and the drive notices by itself.
- 0x6007 abort connection option code = 3: a lost master heartbeat means a quick stop.
- 0x605A quick stop option code = 2: brake on the quick stop ramp (0x6085), then switch the
  power stage off (SWITCH ON DISABLED). Every quick stop ends unpowered at standstill, whoever
  asked for it: the master, its command guard, or the drive itself on a lost heartbeat, when
  no master is left to switch it off. A rod is never left coasting, nor powered.
- 0x605B shutdown option code = 1 and 0x605C disable operation option code = 1: a shutdown or
  disable-operation command from any tool brakes on the slow-down ramp (0x6084) before the
  power stage goes off, instead of letting the rod coast.
- 0x605E fault reaction option code = 2: a fault the drive can still brake through stops on
  the quick stop ramp before the power stage goes off.
- 0x6084 / 0x6085: both ramps at the joint's ``max_acceleration``, the hardest the targets
  ever ask of it, so a stop from top speed takes ``max_speed / max_acceleration`` (80 ms for
  the keeper's slide, 105 ms for its spin with the shipped limits).
"""

from __future__ import annotations

import canopen

from foosball_gym.real_table.hardware.cia402.protocol import (
    ABORT_CONNECTION_OPTION_CODE,
    ABORT_CONNECTION_QUICK_STOP,
    COMMUNICATION_CYCLE_PERIOD,
    CONSUMER_HEARTBEAT_TIME,
    DISABLE_OPERATION_OPTION_CODE,
    FAULT_REACTION_OPTION_CODE,
    FAULT_REACTION_QUICK_STOP,
    INTERPOLATION_TIME_PERIOD,
    MODES_OF_OPERATION_DISPLAY,
    POSITION_ACTUAL,
    PRODUCER_HEARTBEAT_TIME,
    PROFILE_ACCELERATION,
    PROFILE_DECELERATION,
    PROFILE_VELOCITY,
    QUICK_STOP_DECELERATION,
    QUICK_STOP_OPTION_CODE,
    QUICK_STOP_THEN_SWITCH_OFF,
    SHUTDOWN_OPTION_CODE,
    SLOW_DOWN_THEN_DISABLE,
    STATUSWORD,
    TARGET_POSITION,
    VELOCITY_ACTUAL,
)
from foosball_gym.real_table.hardware.config import JointConfig

# An SDO write: object index, sub-index (None for a plain variable), value.
Write = tuple[int, int | None, int]


def stop_settings(
    joint: JointConfig, heartbeat_timeout_s: float, master_node_id: int | None
) -> list[Write]:
    """The heartbeats, stop reactions and ramps, in the order they are written.

    ``master_node_id`` None leaves the drive's consumer heartbeat (and what it does when the
    master's heartbeat is lost) alone.
    """
    period_ms = max(1, round(heartbeat_timeout_s * 1000 / 3))
    writes: list[Write] = [(PRODUCER_HEARTBEAT_TIME, None, period_ms)]
    if master_node_id is not None:
        timeout_ms = min(0xFFFF, max(1, round(heartbeat_timeout_s * 1000)))
        writes += [
            (CONSUMER_HEARTBEAT_TIME, 1, (master_node_id << 16) | timeout_ms),
            (ABORT_CONNECTION_OPTION_CODE, None, ABORT_CONNECTION_QUICK_STOP),
        ]
    assert joint.max_acceleration is not None  # JointConfig fills in its default
    acceleration = abs(joint.speed_to_increments(joint.max_acceleration))
    return [
        *writes,
        (QUICK_STOP_OPTION_CODE, None, QUICK_STOP_THEN_SWITCH_OFF),
        (SHUTDOWN_OPTION_CODE, None, SLOW_DOWN_THEN_DISABLE),
        (DISABLE_OPERATION_OPTION_CODE, None, SLOW_DOWN_THEN_DISABLE),
        (FAULT_REACTION_OPTION_CODE, None, FAULT_REACTION_QUICK_STOP),
        (QUICK_STOP_DECELERATION, None, acceleration),
        (PROFILE_DECELERATION, None, acceleration),
    ]


def mode_settings(joint: JointConfig, mode: str, control_hz: float) -> list[Write]:
    """csp: the SYNC period (written once the PDOs are mapped); pp: the profile's speed and
    acceleration."""
    if mode == "csp":
        return [
            (COMMUNICATION_CYCLE_PERIOD, None, round(1e6 / control_hz)),
            # The SYNC period in units of 10^-4 s, the finest an 8-bit count covers at 60 Hz.
            (INTERPOLATION_TIME_PERIOD, 1, round(1e4 / control_hz)),
            (INTERPOLATION_TIME_PERIOD, 2, -4),
        ]
    # JointConfig fills in the defaults of those left None.
    assert joint.max_speed is not None and joint.max_acceleration is not None
    return [
        (PROFILE_VELOCITY, None, abs(joint.speed_to_increments(joint.max_speed))),
        (PROFILE_ACCELERATION, None, abs(joint.speed_to_increments(joint.max_acceleration))),
    ]


def lay_out_csp_pdos(node: canopen.RemoteNode) -> None:
    """RPDO1: target; TPDO1: statusword, position; TPDO2: velocity, mode display.

    Sets the node's PDO maps only; saving them writes them into the drive. The other PDOs are
    switched off, so nothing else a drive was set up to send competes for the bus. RPDO1 and
    the TPDOs are synchronous (transmission type 1): the drive takes the target and samples its
    state on every SYNC.
    """
    for pdos in (node.rpdo, node.tpdo):
        assert pdos.map is not None  # RPDO and TPDO objects make their maps
        for pdo in pdos.map.values():
            pdo.clear()
            pdo.cob_id = pdo.predefined_cob_id
            pdo.enabled = False
            pdo.trans_type = None
    layout = (
        (node.rpdo[1], (TARGET_POSITION,)),
        (node.tpdo[1], (STATUSWORD, POSITION_ACTUAL)),
        (node.tpdo[2], (VELOCITY_ACTUAL, MODES_OF_OPERATION_DISPLAY)),
    )
    for pdo, objects in layout:
        for index in objects:
            pdo.add_variable(index)
        pdo.trans_type = 1
        pdo.enabled = True
