"""One simulated drive: a C5-E look-alike, a ``canopen.LocalNode`` that moves one joint.

As far as a CANopen master can tell, a :class:`SimulatedDrive` is a CiA 402 position drive:
NMT and heartbeat, SDO access to its objects, PDOs as the master maps them (synchronous RPDOs
are taken on SYNC), the CiA 402 state machine driven by the controlword
(:mod:`~foosball_gym.real_table.virtual.drive_states`), modes 1 (profile position) and 8 (cyclic
synchronous position) with their display, EMCY on faults. Each control step it says where its
joint should go (:meth:`SimulatedDrive.command`).

How a drive stops, as its objects say (see :mod:`foosball_gym.real_table.hardware.cia402.bring_up`):

- a quick stop (controlword, or a lost master heartbeat with 0x6007 = 3) brakes from the
  joint's velocity at the quick stop deceleration (0x6085) or, for option codes 1 and 5 of
  0x605A, the profile deceleration (0x6084); codes 5-8 then hold the joint in QUICK STOP ACTIVE
  (statusword bit 10 set once halted), codes 1-4 switch off after the ramp, code 0 at once;
- shutdown and disable operation from "operation enabled" brake on the slow-down ramp first
  with option code 1 (0x605B, 0x605C), and cut the power at once with 0; a fault likewise
  brakes per 0x605E (the state shows FAULT at once, not FAULT REACTION ACTIVE);
- a drive whose power stage is off does not hold its joint: it coasts on at the velocity it
  had when the power went (the joints of the simulation have no friction to speak of), until
  an end stop; one at rest stays at rest.

Consumer heartbeat (0x1016): a drive watches each node id configured there from the first
heartbeat it hears from it; when one is older than its time, it sends EMCY 0x8130 and reacts
as 0x6007 says (1 fault, 2 disable voltage, 3 quick stop). The age is measured on the table's
``clock``, checked once per control step.

Every controlword, PDO, SYNC and stop a drive sees is kept in :attr:`SimulatedDrive.events`
with the table's time, so tests can tell what happened in which order.
"""

from __future__ import annotations

import collections
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import canopen
from canopen.objectdictionary import ODVariable
from canopen.pdo import PdoMap
from canopen.sdo import SdoAbortedError

from foosball_gym.real_table.hardware.cia402.object_dictionary import object_dictionary
from foosball_gym.real_table.hardware.cia402.protocol import (
    ABORT_CONNECTION_OPTION_CODE,
    CONSUMER_HEARTBEAT_TIME,
    CONTROLWORD,
    CW_DISABLE_VOLTAGE,
    CW_FAULT_RESET,
    CW_NEW_SET_POINT,
    CW_QUICK_STOP,
    DISABLE_OPERATION_OPTION_CODE,
    ERROR_REGISTER,
    FAULT_REACTION_OPTION_CODE,
    MODE_CODES,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    OPERATION_ENABLED,
    POSITION_ACTUAL,
    PROFILE_ACCELERATION,
    PROFILE_DECELERATION,
    PROFILE_VELOCITY,
    QUICK_STOP_DECELERATION,
    QUICK_STOP_OPTION_CODE,
    SHUTDOWN_OPTION_CODE,
    STATUSWORD,
    SW_TARGET_REACHED,
    TARGET_POSITION,
    VELOCITY_ACTUAL,
)
from foosball_gym.real_table.hardware.config import JointConfig
from foosball_gym.real_table.hardware.safety import JointLimits, TargetLimiter
from foosball_gym.real_table.virtual.drive_states import (
    FAULT,
    POWERED,
    QUICK_STOP,
    READY,
    SOD,
    STATE_BITS,
    SW_BIT12,
    SW_REMOTE,
    SWITCHED_ON,
    next_state,
)
from foosball_gym.real_table.virtual.joint_motion import JointMotion

EMCY_HEARTBEAT_LOST = 0x8130  # CiA 301: life guard or heartbeat error
EVENTS_KEPT = 10_000
CSP = MODE_CODES["csp"]
PP = MODE_CODES["pp"]
ERROR_REGISTER_GENERIC = 0x01
SDO_ABORT_VALUE_RANGE = 0x06090030


@dataclass(frozen=True)
class DriveEvent:
    """Something a simulated drive saw or did.

    Attributes:
        t: the table's time.
        what: ``"controlword"``, ``"rpdo"``, ``"sync"``, ``"master heartbeat lost"``,
            ``"halted"`` (a stop ramp ended), ``"power off"`` (the power stage went off).
        value: the controlword written, the node id whose heartbeat was lost, else None.
        state: the CiA 402 state after it.
        statusword: the statusword the master could read just before it.
        speed: how fast the drive was moving the joint just before it (increments/s).
    """

    t: float
    what: str
    value: int | None
    state: str
    statusword: int
    speed: float


def _default(od: canopen.ObjectDictionary, index: int) -> int:
    """The default value of the variable at ``index``.

    Raises:
        ValueError: the object dictionary gives it none.
    """
    variable = od.get_variable(index)
    if variable is None or variable.default is None:
        raise ValueError(f"the object dictionary has no default for 0x{index:04X}")
    return variable.default


class SimulatedDrive:
    """One simulated drive: a LocalNode and its CiA 402 state.

    Args:
        joint: the joint it moves.
        lock: guards the drive's state between the bus's receive thread and the caller.
        position: the joint's position (m or rad) at power-on.
        dt: the simulation's control step, the period of the pp profile and the ramps.
        clock: the table's clock, for the events and the consumer heartbeat.
        on_watch: called with a node id the drive is told to watch the heartbeat of.

    Attributes (in drive units):
        node: the ``canopen.LocalNode``.
        state: the CiA 402 state name.
        controlword: the last controlword written.
        mode, mode_display: modes of operation (0x6060, 0x6061).
        target_position: object 0x607A as last written.
        target: the position, in increments, the joint is driven to (or held at).
        position, velocity: the joint's state as last published, in increments (per s).
        motion: ``"driven"`` (following its target), ``"ramp"`` (braking), ``"hold"``
            (halted under power) or ``"free"`` (power stage off: coasting, or at rest).
        speed: the drive's own velocity in a ramp or while coasting (increments/s).
        events: what it saw and did (:class:`DriveEvent`), oldest first.
    """

    def __init__(
        self,
        joint: JointConfig,
        lock: threading.RLock,
        position: float,
        dt: float,
        clock: Callable[[], float] = time.monotonic,
        on_watch: Callable[[int], None] | None = None,
    ) -> None:
        self.joint = joint
        self._dt = dt
        self.clock = clock
        self._on_watch = on_watch
        self.node = canopen.LocalNode(joint.node_id, object_dictionary(joint.node_id))
        self._lock = lock
        self.state = SOD
        self.controlword = 0
        self.mode = 0
        self.mode_display = 0
        self.target_position = 0
        self.position = joint.to_increments(position)
        self.velocity = 0
        self.target = self.position
        self.error_register = 0
        self._set_point_acknowledged = False
        self._profile_speed = 0
        self._profile_acceleration = 0
        self._pending: dict[tuple[int, int], bytes] = {}  # synchronous RPDO data until SYNC
        self._motion = JointMotion(joint, dt, self.position)
        self._after_ramp: str | None = None  # the state a ramp ends in; None: hold
        od = self.node.object_dictionary
        self._options = {
            index: _default(od, index)
            for index in (
                QUICK_STOP_OPTION_CODE,
                SHUTDOWN_OPTION_CODE,
                DISABLE_OPERATION_OPTION_CODE,
                FAULT_REACTION_OPTION_CODE,
                ABORT_CONNECTION_OPTION_CODE,
            )
        }
        self._quick_stop_deceleration = 0
        self._profile_deceleration = 0
        self._watched: dict[int, tuple[int, float]] = {}  # sub-index: (node id, timeout s)
        self._heard: dict[int, float] = {}  # node id: when its last heartbeat came
        self._lost: set[int] = set()
        self.events: collections.deque[DriveEvent] = collections.deque(maxlen=EVENTS_KEPT)
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)
        assert self.node.rpdo.map is not None  # an RPDO object makes its maps
        for pdo in self.node.rpdo.map.values():
            pdo.add_callback(self._on_rpdo)

    @property
    def statusword(self) -> int:
        word = STATE_BITS[self.state] | SW_REMOTE
        if self.state == OPERATION_ENABLED and (
            self.mode == CSP or (self.mode == PP and self._set_point_acknowledged)
        ):
            word |= SW_BIT12
        if self.state == QUICK_STOP and self.motion == "hold":
            word |= SW_TARGET_REACHED
        return word

    @property
    def motion(self) -> str:
        return self._motion.kind

    @property
    def speed(self) -> float:
        return self._motion.speed

    @property
    def moving_speed(self) -> float:
        """How fast the drive moves its joint now (increments/s): its own speed in a ramp or
        coasting, the joint's last published speed when driven, 0 when holding."""
        return self._motion.moving_speed(self.velocity)

    def _log(self, what: str, value: int | None, statusword: int, speed: float) -> None:
        self.events.append(DriveEvent(self.clock(), what, value, self.state, statusword, speed))

    def boot(self) -> None:
        """Power on: a boot-up message, then NMT pre-operational, as CiA 301 has it."""
        self.node.nmt.state = "RESET"
        self.node.nmt.state = "PRE-OPERATIONAL"

    # ------------------------------------------------------------------ object access

    def _on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        with self._lock:
            if index == STATUSWORD:
                return self.statusword
            if index == MODES_OF_OPERATION_DISPLAY:
                return self.mode_display
            if index == POSITION_ACTUAL:
                return self.position
            if index == VELOCITY_ACTUAL:
                return self.velocity
            if index == ERROR_REGISTER:
                return self.error_register
        return None  # the node's stored value

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        value = od.decode_raw(data)
        if not isinstance(value, int):
            return  # every object handled below is an integer
        with self._lock:
            if index == CONTROLWORD:
                statusword, speed = self.statusword, self.moving_speed
                self._on_controlword(value)
                self._log("controlword", value, statusword, speed)
            elif index in self._options:
                self._options[index] = value
            elif index == QUICK_STOP_DECELERATION:
                self._quick_stop_deceleration = value
            elif index == PROFILE_DECELERATION:
                self._profile_deceleration = value
            elif index == CONSUMER_HEARTBEAT_TIME and subindex > 0:
                node_id, ms = (value >> 16) & 0x7F, value & 0xFFFF
                if ms and node_id:
                    self._watched[subindex] = (node_id, ms / 1000)
                    # Watching starts at the first heartbeat heard after this.
                    self._heard.pop(node_id, None)
                    self._lost.discard(node_id)
                    if self._on_watch is not None:
                        self._on_watch(node_id)
                else:
                    self._watched.pop(subindex, None)
            elif index == MODES_OF_OPERATION:
                if value not in (CSP, PP):
                    raise SdoAbortedError(SDO_ABORT_VALUE_RANGE)
                self.mode = self.mode_display = value
            elif index == TARGET_POSITION:
                self.target_position = value
                if self.state == OPERATION_ENABLED and self.mode == CSP:
                    self.target = value
            elif index == PROFILE_VELOCITY:
                self._profile_speed = value
            elif index == PROFILE_ACCELERATION:
                self._profile_acceleration = value

    # ------------------------------------------------------------------ CiA 402

    def _on_controlword(self, cw: int) -> None:
        previous, self.controlword = self.controlword, cw
        state = self.state
        if state == FAULT:
            if cw & CW_FAULT_RESET and not previous & CW_FAULT_RESET:
                self.error_register = 0
                self._enter(SOD)
                self.node.emcy.reset()
            return
        self._enter(self._next_state(cw))
        if self.state == OPERATION_ENABLED and self.mode == PP:
            if cw & CW_NEW_SET_POINT and not previous & CW_NEW_SET_POINT:
                self.target = self.target_position
                self._set_point_acknowledged = True
            elif not cw & CW_NEW_SET_POINT:
                self._set_point_acknowledged = False

    def _next_state(self, cw: int) -> str:
        return next_state(self.state, cw, self._options[QUICK_STOP_OPTION_CODE])

    def _enter(self, state: str) -> None:
        if state == self.state:
            return
        previous = self.state
        self.state = state
        if state == OPERATION_ENABLED:
            # A drive that is switched on holds where it is until it gets a target.
            self.target = self.position
            self._set_point_acknowledged = False
            self._motion.follow(self._profile_generator())
            return
        if previous == OPERATION_ENABLED:
            option = {
                QUICK_STOP: QUICK_STOP_OPTION_CODE,
                READY: SHUTDOWN_OPTION_CODE,
                SWITCHED_ON: DISABLE_OPERATION_OPTION_CODE,
                FAULT: FAULT_REACTION_OPTION_CODE,
            }.get(state)
            self._react(option)
        elif previous == QUICK_STOP and state == FAULT and self.motion == "ramp":
            self._react(FAULT_REACTION_OPTION_CODE)
        elif state not in POWERED and self.motion != "free":
            self._power_off()

    def _react(self, option: int | None) -> None:
        """Leaving "operation enabled": brake as the option code says, or cut the power."""
        code = self._options[option] if option is not None else 0
        quick = self._quick_stop_deceleration
        slow = self._profile_deceleration or quick
        if option == QUICK_STOP_OPTION_CODE:
            if code == 0:
                self.state = SOD
                self._power_off()
                return
            deceleration = slow if code in (1, 5) else quick
            after = SOD if code <= 4 else None
        elif option == FAULT_REACTION_OPTION_CODE:
            if code == 0:
                self._power_off()
                return
            deceleration = slow if code == 1 else quick
            after = self.state
        else:  # shutdown, disable operation: 1 slows down first, 0 (or none) does not
            if code != 1:
                self._power_off()
                return
            deceleration = slow
            after = self.state
        self._start_ramp(deceleration, after)

    def _start_ramp(self, deceleration: float, after: str | None) -> None:
        self._after_ramp = after
        if self._motion.brake(deceleration, self.position, self.velocity):
            self._halt()  # no ramp configured: stop on the spot

    def _halt(self) -> None:
        statusword = self.statusword
        self._motion.halt(hold=self._after_ramp is None)
        self._log("halted", None, statusword, 0.0)
        if self._after_ramp is not None:
            self.state = self._after_ramp
            self._log("power off", None, statusword, 0.0)

    def _power_off(self) -> None:
        """The power stage goes off: the joint keeps the speed it had and coasts."""
        statusword, speed = self.statusword, self.moving_speed
        self._motion.power_off(self.position, self.velocity)
        self._log("power off", None, statusword, speed)

    def _profile_generator(self) -> TargetLimiter | None:
        """pp: the drive's own ramp to each new target, None where it was not given one."""
        joint = self.joint
        if self.mode != PP or not (self._profile_speed and self._profile_acceleration):
            return None
        limits = JointLimits(
            -joint.hard_limit,
            joint.hard_limit,
            abs(joint.speed_from_increments(self._profile_speed)),
            abs(joint.speed_from_increments(self._profile_acceleration)),
        )
        return TargetLimiter(limits, self._dt, joint.from_increments(self.position))

    def fault(self, code: int, send_emcy: bool) -> None:
        with self._lock:
            self.error_register |= ERROR_REGISTER_GENERIC
            self._enter(FAULT)
            register = self.error_register
        if send_emcy:
            self.node.emcy.send(code, register)

    # ------------------------------------------------------------------ consumer heartbeat

    def heard(self, node_id: int) -> None:
        """A heartbeat of ``node_id`` came (the bus's receive thread)."""
        with self._lock:
            self._heard[node_id] = self.clock()
            self._lost.discard(node_id)

    def supervise(self) -> None:
        """React to every watched heartbeat older than its time, once per silence."""
        now = self.clock()
        lost = []
        with self._lock:
            for node_id, timeout in self._watched.values():
                heard = self._heard.get(node_id)
                if heard is None or node_id in self._lost or now - heard <= timeout:
                    continue
                self._lost.add(node_id)
                lost.append(node_id)
                statusword, speed = self.statusword, self.moving_speed
                action = self._options[ABORT_CONNECTION_OPTION_CODE]
                if action == 1:
                    self.error_register |= ERROR_REGISTER_GENERIC
                    self._enter(FAULT)
                elif action == 2:
                    self._enter(self._next_state(CW_DISABLE_VOLTAGE))
                elif action == 3:
                    self._enter(self._next_state(CW_QUICK_STOP))
                self._log("master heartbeat lost", node_id, statusword, speed)
            register = self.error_register
        for _ in lost:
            self.node.emcy.send(EMCY_HEARTBEAT_LOST, register)

    # ------------------------------------------------------------------ PDOs

    def _on_rpdo(self, pdo: PdoMap) -> None:
        if self.node.nmt.state != "OPERATIONAL":
            return
        with self._lock:
            self._log("rpdo", None, self.statusword, self.moving_speed)
        for var in pdo:
            data = bytes(var.get_data())
            if pdo.trans_type is not None and pdo.trans_type <= 240:
                with self._lock:
                    self._pending[(var.index, var.subindex)] = data
            else:
                self.node.set_data(var.index, var.subindex, data)

    def on_sync(self) -> None:
        with self._lock:
            if self.node.nmt.state == "OPERATIONAL":
                self._log("sync", None, self.statusword, self.moving_speed)
            pending, self._pending = self._pending, {}
            for (index, subindex), data in pending.items():
                self.node.set_data(index, subindex, data)

    def on_nmt(self) -> None:
        """Follow NMT: PDOs exist in "operational" only, as mapped when it was entered."""
        with self._lock:
            self._pending = {}
            if self.node.nmt.state == "OPERATIONAL":
                self.node.rpdo.read()
                self.node.tpdo.read()

    def send_tpdos(self) -> None:
        if self.node.nmt.state != "OPERATIONAL":
            return
        assert self.node.tpdo.map is not None  # a TPDO object makes its maps
        for pdo in self.node.tpdo.map.values():
            if pdo.enabled:
                for var in pdo:
                    var.set_data(self.node.get_data(var.index, var.subindex))
                pdo.transmit()

    # ------------------------------------------------------------------ the joint

    def command(self) -> float:
        """Where the joint should go this control step (m or rad), one step of the drive's
        motion on from the last."""
        goal, setpoint, halted = self._motion.step(self.target, use_profile=self.mode == PP)
        if halted:
            self._halt()
        if setpoint is not None:
            self.target = round(setpoint)
        return goal
