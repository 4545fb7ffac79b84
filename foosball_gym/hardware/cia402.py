"""One CiA 402 drive on CANopen (a Nanotec C5-E in the paper's table).

:class:`Cia402Drive` brings one drive from whatever state it is in (a fault included) to
"operation enabled" in the configured mode, sends it targets in SI units, reads its position
and velocity back, stops it, and reports its faults: the statusword's fault bit, EMCY messages
and a lost or unexpected heartbeat, each with the node id and the reason.

What bring-up sets so that a drive stops safely on its own (CiA 301 / CiA 402):

- 0x1017 producer heartbeat time: the drive beats three times per heartbeat timeout, so the
  master notices a dead drive.
- 0x1016 consumer heartbeat time, sub-index 1: the master's node id and the heartbeat timeout.
  The master beats from a thread of its own (``TableDrives``); a master that is killed, hangs
  with the interpreter stuck, or loses the bus stops beating, and the drive notices by itself.
- 0x6007 abort connection option code = 3: a lost master heartbeat means a quick stop.
- 0x605A quick stop option code = 6: brake on the quick stop ramp (0x6085), then stay in QUICK
  STOP ACTIVE holding the position under power; a stopped rod neither coasts nor swings.
- 0x605B shutdown option code = 1 and 0x605C disable operation option code = 1: a shutdown or
  disable-operation command from any tool brakes on the slow-down ramp (0x6084) before the
  power stage goes off, instead of letting the rod coast.
- 0x605E fault reaction option code = 2: a fault the drive can still brake through stops on
  the quick stop ramp before the power stage goes off.
- 0x6084 / 0x6085: both ramps at the joint's ``max_acceleration``, the hardest the targets
  ever ask of it, so a stop from top speed takes ``max_speed / max_acceleration`` (80 ms for
  the keeper's slide, 105 ms for its spin with the shipped limits).

Every stop of the master brakes first and cuts power only once the drive reports standstill
(:meth:`Cia402Drive.wait_until_stopped`): cutting it during the ramp would leave the rod
coasting.

The CiA 402 state machine is driven here over confirmed SDO writes rather than with
``canopen.profiles.p402.BaseNode402``: that helper cannot reset a fault without running into
its own timeout, logs and swallows a failed mode change, and warns on every statusword read
that is not in a PDO. Its state table (:class:`~canopen.profiles.p402.State402`) is used.

Modes (``TableConfig.mode``):

- ``"csp"``: RPDO1 carries the target position and is taken by the drive on the next SYNC;
  TPDO1 (statusword, position) and TPDO2 (velocity, mode display) answer every SYNC.
- ``"pp"``: everything over SDO: target position, the new-set-point handshake of the
  controlword (bit 4 up, wait for the statusword's set-point acknowledge, bit 4 down) and the
  actual values.
"""

from __future__ import annotations

import contextlib
import logging
import struct
import threading
import time
from collections.abc import Iterator

import can
import canopen
from canopen.emcy import EmcyError
from canopen.nmt import NMT_STATES, NmtError
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
from canopen.profiles.p402 import State402
from canopen.sdo.exceptions import SdoError

from foosball_gym.hardware.config import JointConfig
from foosball_gym.hardware.safety import DriveFault

logger = logging.getLogger(__name__)

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
# 0x605A = 6: slow down on the quick stop ramp, then stay in QUICK STOP ACTIVE, holding the
# position under power (a stopped rod holds still rather than being free to swing).
QUICK_STOP_AND_HOLD = 6
# 0x605B, 0x605C = 1: slow down on the slow-down ramp, then switch the power stage off.
SLOW_DOWN_THEN_DISABLE = 1
# 0x605E = 2: the fault reaction brakes on the quick stop ramp.
FAULT_REACTION_QUICK_STOP = 2
# 0x6007 = 3: a lost connection to the master (its heartbeat) quick-stops the drive.
ABORT_CONNECTION_QUICK_STOP = 3
CONSUMER_HEARTBEAT_ENTRIES = 4
# A drive turning slower than this fraction of its joint's top speed counts as standing still.
STANDSTILL_FRACTION = 0.001
# The wait for standstill ends at this multiple of the ramp's length plus STOP_SLACK_S, whatever
# the drive reports.
STOP_TIME_FACTOR = 1.5
STOP_SLACK_S = 0.05

OPERATION_ENABLED = "OPERATION ENABLED"
NMT_OPERATIONAL = 5
NMT_BOOT_UP = 0

_STATE_MASKS = tuple(State402.SW_MASK.items())


def state_name(statusword: int) -> str:
    """The CiA 402 state a statusword shows (``"OPERATION ENABLED"``, ``"FAULT"``, ...)."""
    for name, (mask, value) in _STATE_MASKS:
        if statusword & mask == value:
            return name
    return "UNKNOWN"


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


class Cia402Drive:
    """One drive of the table, through a ``canopen.RemoteNode``.

    Args:
        network: the connected CANopen network the drive is on.
        joint: the joint it moves and its calibration.
        mode: ``"csp"`` or ``"pp"``.
        control_hz: the control rate (the SYNC rate in csp).
        heartbeat_timeout_s: how old the drive's last heartbeat may be, and how old the
            master's may be before the drive quick-stops itself.
        master_node_id: the node id the master's heartbeat comes from; None leaves the drive's
            consumer heartbeat alone.

    Every method that talks to the drive raises :class:`DriveFault` (node id and reason) when
    the drive does not answer or refuses. The methods may be called from several threads (the
    play loop, the command guard): one transfer or handshake with the drive at a time.
    """

    STATE_TIMEOUT_S = 0.5  # per CiA 402 transition, and for the mode display to follow
    POLL_S = 0.001

    def __init__(
        self,
        network: canopen.Network,
        joint: JointConfig,
        *,
        mode: str,
        control_hz: float,
        heartbeat_timeout_s: float,
        master_node_id: int | None = None,
    ) -> None:
        if mode not in MODE_CODES:
            raise ValueError(f"unknown drive mode {mode!r}; allowed: {', '.join(MODE_CODES)}")
        self.joint = joint
        self.mode = mode
        self.control_hz = control_hz
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.master_node_id = master_node_id
        # An SDO client serves one transfer at a time; a quick stop from the guard's thread
        # must also never land inside the play loop's set-point handshake, whose last write
        # would enable the drive again.
        self._lock = threading.RLock()
        self.node = canopen.RemoteNode(joint.node_id, object_dictionary(joint.node_id))
        network.add_node(self.node)
        self.network = network
        #: True from a finished bring-up to the next stop: a drive that leaves "operation
        #: enabled" in between is at fault.
        self.enabled = False
        self._pdo = False
        # What the receive thread reports; guarded by this condition's lock.
        self._changed = threading.Condition()
        self._statusword: int | None = None
        self._position: int | None = None
        self._velocity: int | None = None
        self._mode_display: int | None = None
        self._received = [0, 0]  # TPDO1, TPDO2 so far
        self._sync_mark: tuple[int, int] | None = None
        self._emcy: EmcyError | None = None
        self._heartbeat_at: float | None = None
        self._heartbeat_state: int | None = None
        self._expect_nmt: int | None = None
        self.node.emcy.add_callback(self._on_emcy)
        self.node.nmt.add_heartbeat_callback(self._on_heartbeat)
        self.node.tpdo[1].add_callback(self._on_tpdo1)
        self.node.tpdo[2].add_callback(self._on_tpdo2)
        self._rpdo = self.node.rpdo[1]
        self._target: canopen.pdo.PdoVariable | None = None  # RPDO1's target, once mapped

    # ------------------------------------------------------------------ receive thread

    def _on_emcy(self, error: EmcyError) -> None:
        if error.code & 0xFF00 == 0:
            return  # "error reset / no error": it clears nothing the master has seen
        with self._changed:
            if self._emcy is None:
                self._emcy = error

    def _on_heartbeat(self, state: int) -> None:
        with self._changed:
            self._heartbeat_at = time.monotonic()
            self._heartbeat_state = state
            self._changed.notify_all()

    def _on_tpdo1(self, pdo: canopen.pdo.PdoMap) -> None:
        statusword, position = struct.unpack_from("<Hi", pdo.data)
        with self._changed:
            self._statusword, self._position = statusword, position
            self._received[0] += 1
            self._changed.notify_all()

    def _on_tpdo2(self, pdo: canopen.pdo.PdoMap) -> None:
        velocity, mode = struct.unpack_from("<ib", pdo.data)
        with self._changed:
            self._velocity, self._mode_display = velocity, mode
            self._received[1] += 1
            self._changed.notify_all()

    # ------------------------------------------------------------------ SDO helpers

    @contextlib.contextmanager
    def _talking(self, what: str) -> Iterator[None]:
        """Turn the bus's and the SDO client's errors into a :class:`DriveFault`."""
        try:
            yield
        except (SdoError, NmtError, can.CanError) as e:
            raise DriveFault(self.joint, f"{what} failed: {e}") from e

    def _read(self, index: int, subindex: int | None = None) -> int:
        with self._lock, self._talking(f"reading 0x{index:04X}"):
            obj = self.node.sdo[index]
            return (obj if subindex is None else obj[subindex]).raw

    def _write(self, index: int, value: int, subindex: int | None = None) -> None:
        with self._lock, self._talking(f"writing 0x{index:04X} = {value}"):
            obj = self.node.sdo[index]
            (obj if subindex is None else obj[subindex]).raw = value

    def _read_statusword(self) -> int:
        statusword = self._read(STATUSWORD)
        with self._changed:
            self._statusword = statusword
        return statusword

    def _wait_for_state(self, target: str, what: str) -> None:
        deadline = time.monotonic() + self.STATE_TIMEOUT_S
        while True:
            statusword = self._read_statusword()
            if state_name(statusword) == target:
                return
            if time.monotonic() > deadline:
                raise DriveFault(
                    self.joint,
                    f"did not reach {target} after {what} (it is in {state_name(statusword)}, "
                    f"statusword 0x{statusword:04X})",
                )
            time.sleep(self.POLL_S)

    # ------------------------------------------------------------------ bring-up

    def bring_up(self) -> float:
        """Take the drive from any state to "operation enabled" in the configured mode.

        NMT pre-operational; check it is a CiA 402 device; fault reset or disable down to
        "switch on disabled"; heartbeats (its own, and watching the master's), the stop
        reactions and ramps (see the module's docstring), the mode's PDOs or profile; mode of
        operation, checked on its display; target = actual position, so it does not move; NMT
        operational (confirmed by its heartbeat); shutdown, switch on, enable operation.

        Returns:
            The joint's position (m or rad) when it was enabled.
        """
        self.enabled = False
        self._pdo = False
        with self._changed:
            self._expect_nmt = None
            self._sync_mark = None
        with self._talking("NMT pre-operational"):
            self.node.nmt.state = "PRE-OPERATIONAL"
        device_type = self._read(DEVICE_TYPE)
        if device_type & 0xFFFF != DEVICE_PROFILE:
            raise DriveFault(
                self.joint, f"is not a CiA 402 drive (device type 0x{device_type:08X})"
            )
        self._to_switch_on_disabled()
        with self._changed:
            # Whatever it reported before the reset is history now.
            self._emcy = None
        joint = self.joint
        period_ms = max(1, round(self.heartbeat_timeout_s * 1000 / 3))
        self._write(PRODUCER_HEARTBEAT_TIME, period_ms)
        if self.master_node_id is not None:
            timeout_ms = min(0xFFFF, max(1, round(self.heartbeat_timeout_s * 1000)))
            self._write(
                CONSUMER_HEARTBEAT_TIME, (self.master_node_id << 16) | timeout_ms, subindex=1
            )
            self._write(ABORT_CONNECTION_OPTION_CODE, ABORT_CONNECTION_QUICK_STOP)
        self._write(QUICK_STOP_OPTION_CODE, QUICK_STOP_AND_HOLD)
        self._write(SHUTDOWN_OPTION_CODE, SLOW_DOWN_THEN_DISABLE)
        self._write(DISABLE_OPERATION_OPTION_CODE, SLOW_DOWN_THEN_DISABLE)
        self._write(FAULT_REACTION_OPTION_CODE, FAULT_REACTION_QUICK_STOP)
        acceleration = abs(joint.speed_to_increments(joint.max_acceleration))
        self._write(QUICK_STOP_DECELERATION, acceleration)
        self._write(PROFILE_DECELERATION, acceleration)
        if self.mode == "csp":
            self._configure_pdos()
            self._write(COMMUNICATION_CYCLE_PERIOD, round(1e6 / self.control_hz))
            # The SYNC period in units of 10^-4 s, the finest an 8-bit count covers at 60 Hz.
            self._write(INTERPOLATION_TIME_PERIOD, round(1e4 / self.control_hz), subindex=1)
            self._write(INTERPOLATION_TIME_PERIOD, -4, subindex=2)
        else:
            self._write(PROFILE_VELOCITY, abs(joint.speed_to_increments(joint.max_speed)))
            self._write(PROFILE_ACCELERATION, acceleration)
        self._set_mode()
        position = self._read(POSITION_ACTUAL)
        self._write(TARGET_POSITION, position)
        self._go_operational()
        self._write(CONTROLWORD, CW_SHUTDOWN)
        self._wait_for_state("READY TO SWITCH ON", "shutdown (0x06)")
        self._write(CONTROLWORD, CW_SWITCH_ON)
        self._wait_for_state("SWITCHED ON", "switch on (0x07)")
        self._write(CONTROLWORD, CW_ENABLE_OPERATION)
        self._wait_for_state(OPERATION_ENABLED, "enable operation (0x0F)")
        self._pdo = self.mode == "csp"
        self.enabled = True
        return joint.from_increments(position)

    def _to_switch_on_disabled(self) -> None:
        deadline = time.monotonic() + 4 * self.STATE_TIMEOUT_S
        while True:
            statusword = self._read_statusword()
            state = state_name(statusword)
            if state == "SWITCH ON DISABLED":
                return
            if time.monotonic() > deadline:
                with self._changed:
                    emcy = f", last EMCY {_describe(self._emcy)}" if self._emcy else ""
                raise DriveFault(
                    self.joint,
                    f"could not be brought to SWITCH ON DISABLED (it stays in {state}, "
                    f"statusword 0x{statusword:04X}{emcy})",
                )
            if state == "FAULT":
                # The reset acts on a rising edge of bit 7.
                self._write(CONTROLWORD, CW_DISABLE_VOLTAGE)
                self._write(CONTROLWORD, CW_FAULT_RESET)
            elif state in ("NOT READY TO SWITCH ON", "FAULT REACTION ACTIVE"):
                time.sleep(self.POLL_S)  # the drive leaves these states by itself
            else:
                self._write(CONTROLWORD, CW_DISABLE_VOLTAGE)

    def _configure_pdos(self) -> None:
        """RPDO1: target; TPDO1: statusword, position; TPDO2: velocity, mode display.

        The other PDOs are switched off, so nothing else a drive was set up to send competes
        for the bus. RPDO1 and the TPDOs are synchronous (transmission type 1): the drive
        takes the target and samples its state on every SYNC.
        """
        for pdos in (self.node.rpdo, self.node.tpdo):
            for pdo in pdos.map.values():
                pdo.clear()
                pdo.cob_id = pdo.predefined_cob_id
                pdo.enabled = False
                pdo.trans_type = None
        layout = (
            (self.node.rpdo[1], (TARGET_POSITION,)),
            (self.node.tpdo[1], (STATUSWORD, POSITION_ACTUAL)),
            (self.node.tpdo[2], (VELOCITY_ACTUAL, MODES_OF_OPERATION_DISPLAY)),
        )
        for pdo, objects in layout:
            for index in objects:
                pdo.add_variable(index)
            pdo.trans_type = 1
            pdo.enabled = True
        with self._talking("configuring the PDOs"):
            self.node.rpdo.save()
            self.node.tpdo.save()
        self._target = self._rpdo[TARGET_POSITION]

    def _set_mode(self) -> None:
        code = MODE_CODES[self.mode]
        self._write(MODES_OF_OPERATION, code)
        deadline = time.monotonic() + self.STATE_TIMEOUT_S
        while (shown := self._read(MODES_OF_OPERATION_DISPLAY)) != code:
            if time.monotonic() > deadline:
                raise DriveFault(
                    self.joint,
                    f"mode of operation display shows {shown}, expected {code} ({self.mode})",
                )
            time.sleep(self.POLL_S)
        with self._changed:
            self._mode_display = shown

    def _go_operational(self) -> None:
        """NMT operational, confirmed by a heartbeat sent after the command."""
        with self._changed:
            sent = time.monotonic()
            with self._talking("NMT operational"):
                self.node.nmt.state = "OPERATIONAL"
            confirmed = self._changed.wait_for(
                lambda: (
                    self._heartbeat_at is not None
                    and self._heartbeat_at >= sent
                    and self._heartbeat_state == NMT_OPERATIONAL
                ),
                timeout=2 * self.heartbeat_timeout_s,
            )
            if not confirmed:
                state = NMT_STATES.get(self._heartbeat_state, "no heartbeat at all")
                raise DriveFault(
                    self.joint,
                    f"no heartbeat reporting OPERATIONAL within "
                    f"{2 * self.heartbeat_timeout_s * 1e3:.0f} ms of the NMT command "
                    f"(last: {state})",
                )
            self._expect_nmt = NMT_OPERATIONAL

    # ------------------------------------------------------------------ every control step

    def set_target(self, value: float) -> None:
        """Send a position target (m or rad).

        In csp it goes out in RPDO1 and the drive takes it on the next SYNC (which the caller
        sends, once for all drives). In pp it is written and handed over with the set-point
        handshake, confirmed by the drive.
        """
        increments = self.joint.to_increments(value)
        with self._lock:
            if not self.enabled:
                # Stopped meanwhile (by the guard's thread): the handshake's controlword would
                # take the drive out of QUICK STOP ACTIVE again.
                return
            if self._pdo:
                with self._talking("sending RPDO1"):
                    self._target.raw = increments
                    self._rpdo.transmit()
                return
            base = CW_ENABLE_OPERATION | CW_CHANGE_IMMEDIATELY
            self._write(TARGET_POSITION, increments)
            self._write(CONTROLWORD, base | CW_NEW_SET_POINT)
            deadline = time.monotonic() + 1.0 / self.control_hz
            # Bit 4 must stay up until the drive has seen it; a fault ends the wait early and
            # is reported by fault_reason().
            while not (statusword := self._read_statusword()) & (
                SW_SET_POINT_ACKNOWLEDGE | SW_FAULT
            ):
                if time.monotonic() > deadline:
                    raise DriveFault(
                        self.joint,
                        f"did not acknowledge the set-point within one control period "
                        f"(statusword 0x{statusword:04X})",
                    )
            self._write(CONTROLWORD, base)

    def mark_sync(self) -> None:
        """Note that a SYNC is about to go out: :meth:`actual` waits for the answer to it."""
        with self._changed:
            self._sync_mark = (self._received[0], self._received[1])

    def actual(self) -> tuple[float, float]:
        """Position (m or rad) and velocity (m/s or rad/s).

        In csp after a SYNC: the drive's TPDO answer to it, waited for up to one control
        period. Otherwise (pp, or no SYNC since the last read): read over SDO.
        """
        joint = self.joint
        with self._changed:
            mark = self._sync_mark
            if self._pdo and mark is not None:
                answered = self._changed.wait_for(
                    lambda: self._received[0] > mark[0] and self._received[1] > mark[1],
                    timeout=1.0 / self.control_hz,
                )
                if not answered:
                    raise DriveFault(
                        joint,
                        f"no TPDO answer to the SYNC within one control period "
                        f"({1e3 / self.control_hz:.1f} ms)",
                    )
                self._sync_mark = None
                return (
                    joint.from_increments(self._position),
                    joint.speed_from_increments(self._velocity),
                )
        with self._lock:
            position = self._read(POSITION_ACTUAL)
            velocity = self._read(VELOCITY_ACTUAL)
        return joint.from_increments(position), joint.speed_from_increments(velocity)

    # ------------------------------------------------------------------ stopping

    def quick_stop(self) -> None:
        """Quick stop: the drive brakes on its quick stop ramp and holds the position."""
        with self._lock:
            self.enabled = False
            self._write(CONTROLWORD, CW_QUICK_STOP)

    @property
    def stop_time_s(self) -> float:
        """How long a quick stop from the joint's top speed takes on the configured ramp."""
        return self.joint.max_speed / self.joint.max_acceleration

    def wait_until_stopped(self) -> bool:
        """Wait until a quick-stopped drive reports standstill.

        Standstill: QUICK STOP ACTIVE with the statusword's target-reached bit (the drive has
        halted) or an actual velocity near 0. A drive that left QUICK STOP ACTIVE by itself (a
        fault, or an option code that switches off after the ramp) is not waited for. The wait
        is bounded by :data:`STOP_TIME_FACTOR` times :attr:`stop_time_s` plus
        :data:`STOP_SLACK_S`.

        Returns:
            True if the drive reported standstill, False if the bound passed first.
        """
        joint = self.joint
        slow = STANDSTILL_FRACTION * abs(joint.speed_to_increments(joint.max_speed))
        deadline = time.monotonic() + STOP_TIME_FACTOR * self.stop_time_s + STOP_SLACK_S
        while True:
            with self._lock:
                statusword = self._read_statusword()
                if state_name(statusword) != "QUICK STOP ACTIVE":
                    return True
                if statusword & SW_TARGET_REACHED or abs(self._read(VELOCITY_ACTUAL)) <= slow:
                    return True
            if time.monotonic() > deadline:
                return False
            time.sleep(self.POLL_S)

    def disable(self) -> str:
        """Brake to standstill, then take the power stage off.

        A drive in "operation enabled" is quick-stopped first; one in "quick stop active"
        is disabled (disable voltage: shutdown is no transition there) only once it reports
        standstill, or the ramp's time bound passed (logged), so the rod brakes and never
        coasts. "Switched on" drives no motor and goes down by a shutdown.

        Returns:
            The state the drive is left in.
        """
        with self._lock:
            self.enabled = False
            state = state_name(self._read_statusword())
            if state == OPERATION_ENABLED:
                self.quick_stop()
                state = "QUICK STOP ACTIVE"
            if state == "QUICK STOP ACTIVE":
                if not self.wait_until_stopped():
                    logger.warning(
                        "%s: no standstill reported within %.0f ms of the quick stop; "
                        "switching off anyway",
                        self.joint.label,
                        1e3 * (STOP_TIME_FACTOR * self.stop_time_s + STOP_SLACK_S),
                    )
                if state_name(self._read_statusword()) == "QUICK STOP ACTIVE":
                    self._write(CONTROLWORD, CW_DISABLE_VOLTAGE)
            elif state == "SWITCHED ON":
                self._write(CONTROLWORD, CW_SHUTDOWN)
            return state_name(self._read_statusword())

    def release(self) -> None:
        """Stop watching the drive, let it stop watching the master (whose heartbeat ends
        next), and send it back to NMT pre-operational (no PDOs)."""
        self._pdo = False
        with self._changed:
            self._expect_nmt = None
        if self.master_node_id is not None:
            self._write(CONSUMER_HEARTBEAT_TIME, 0, subindex=1)
        with self._lock, self._talking("NMT pre-operational"):
            self.node.nmt.state = "PRE-OPERATIONAL"

    # ------------------------------------------------------------------ faults

    def fault_reason(self) -> str | None:
        """Why the drive is at fault, or None: an EMCY, the statusword, its heartbeat."""
        with self._changed:
            if self._emcy is not None:
                return _describe(self._emcy)
            statusword = self._statusword
            if statusword is not None:
                state = state_name(statusword)
                if statusword & SW_FAULT:
                    return f"statusword 0x{statusword:04X} has the fault bit set ({state})"
                if self.enabled and state != OPERATION_ENABLED:
                    return f"left {OPERATION_ENABLED} for {state} (statusword 0x{statusword:04X})"
            if self.enabled and self._pdo and self._mode_display != MODE_CODES[self.mode]:
                return (
                    f"mode of operation display shows {self._mode_display}, expected "
                    f"{MODE_CODES[self.mode]} ({self.mode})"
                )
            if self._expect_nmt is None:
                return None
            if self._heartbeat_state == NMT_BOOT_UP:
                return "rebooted (boot-up message on the heartbeat)"
            if self._heartbeat_state != self._expect_nmt:
                shown = NMT_STATES.get(self._heartbeat_state, self._heartbeat_state)
                return f"heartbeat reports NMT state {shown}, expected OPERATIONAL"
            age = time.monotonic() - self._heartbeat_at
            if age > self.heartbeat_timeout_s:
                return (
                    f"heartbeat lost: none for {age * 1e3:.0f} ms (timeout "
                    f"{self.heartbeat_timeout_s * 1e3:.0f} ms)"
                )
        return None


def _describe(error: EmcyError) -> str:
    return f"EMCY {error} (error register 0x{error.register:02X})"
