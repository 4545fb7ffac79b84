"""Simulated drives: C5-E look-alikes on a virtual CAN bus that move the simulated rods.

:class:`SimulatedDrives` puts one ``canopen.LocalNode`` per configured joint on a python-can
``virtual`` channel. As far as a CANopen master can tell, each is a CiA 402 position drive: NMT
and heartbeat, SDO access to its objects, PDOs as the master maps them (synchronous RPDOs are
taken on SYNC), the CiA 402 state machine driven by the controlword, modes 1 (profile
position) and 8 (cyclic synchronous position) with their display, EMCY on faults. Behind it,
each node's joint of a :class:`~foosball_gym.simulator.TableSim` follows the node's target;
a node that is not in "operation enabled" (quick stop included) holds its joint where it was.

The caller steps the simulation; one control step in lockstep is:

1. the master sends (``TableDrives.command``: targets and, in csp, a SYNC),
2. :meth:`SimulatedDrives.apply` waits until the nodes have processed everything sent so
   far, then commands the rods,
3. the caller steps the simulation (``sim.step()``),
4. :meth:`SimulatedDrives.publish` stores the rods' positions and velocities in the nodes and
   sends their TPDOs,
5. the master reads (``TableDrives.read``: in csp it waits for those TPDOs).

This is the only hardware-side module that uses the simulator, and it only calls the
``TableSim`` it is given.
"""

from __future__ import annotations

import threading
from collections.abc import Mapping
from typing import TYPE_CHECKING

import canopen
from canopen.objectdictionary import ODVariable
from canopen.pdo import PdoMap
from canopen.sdo import SdoAbortedError

from foosball_gym.hardware.cia402 import (
    CONTROLWORD,
    CW_FAULT_RESET,
    CW_NEW_SET_POINT,
    ERROR_REGISTER,
    MODE_CODES,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    OPERATION_ENABLED,
    POSITION_ACTUAL,
    PROFILE_ACCELERATION,
    PROFILE_VELOCITY,
    STATUSWORD,
    TARGET_POSITION,
    VELOCITY_ACTUAL,
    object_dictionary,
)
from foosball_gym.hardware.config import Joint, JointConfig, TableConfig
from foosball_gym.hardware.safety import JointLimits, TargetLimiter

if TYPE_CHECKING:
    from foosball_gym.simulator import TableSim

# A 29-bit frame the nodes' network sends to itself to learn that everything before it has
# been processed; CANopen devices use 11-bit identifiers only and never look at it.
FLUSH_ID = 0x1FFFFFFF
FLUSH_TIMEOUT_S = 1.0
NOTIFIER_CYCLE_S = 0.1
SYNC_ID = 0x80
NMT_ID = 0x000

CSP = MODE_CODES["csp"]
PP = MODE_CODES["pp"]

SOD = "SWITCH ON DISABLED"
READY = "READY TO SWITCH ON"
SWITCHED_ON = "SWITCHED ON"
QUICK_STOP = "QUICK STOP ACTIVE"
FAULT = "FAULT"
# Statusword bits 0-6 of each state (voltage enabled included), as a C5-E shows them.
STATE_BITS = {
    SOD: 0x40,
    READY: 0x31,
    SWITCHED_ON: 0x33,
    OPERATION_ENABLED: 0x37,
    QUICK_STOP: 0x17,
    FAULT: 0x08,
}
SW_REMOTE = 0x0200
SW_BIT12 = 0x1000  # pp: set-point acknowledge; csp: the drive follows the command value
ERROR_REGISTER_GENERIC = 0x01
SDO_ABORT_VALUE_RANGE = 0x06090030


class SimulatedDrive:
    """One simulated drive: a LocalNode and its CiA 402 state.

    Args:
        joint: the joint it moves.
        lock: guards the drive's state between the bus's receive thread and the caller.
        position: the joint's position (m or rad) at power-on.
        dt: the simulation's control step, the period of the pp profile.

    Attributes (in drive units):
        node: the ``canopen.LocalNode``.
        state: the CiA 402 state name.
        controlword: the last controlword written.
        mode, mode_display: modes of operation (0x6060, 0x6061).
        target_position: object 0x607A as last written.
        target: the position, in increments, the joint is driven to (or held at).
        position, velocity: the joint's state as last published, in increments (per s).
    """

    def __init__(
        self, joint: JointConfig, lock: threading.RLock, position: float, dt: float
    ) -> None:
        self.joint = joint
        self._dt = dt
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
        self._profile: TargetLimiter | None = None
        self._pending: dict[tuple[int, int], bytes] = {}  # synchronous RPDO data until SYNC
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)
        for pdo in self.node.rpdo.map.values():
            pdo.add_callback(self._on_rpdo)

    @property
    def statusword(self) -> int:
        word = STATE_BITS[self.state] | SW_REMOTE
        if self.state == OPERATION_ENABLED and (
            self.mode == CSP or (self.mode == PP and self._set_point_acknowledged)
        ):
            word |= SW_BIT12
        return word

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
        with self._lock:
            if index == CONTROLWORD:
                self._on_controlword(value)
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
        if not cw & 0x02:  # disable voltage
            new = SOD if state in (READY, SWITCHED_ON, OPERATION_ENABLED, QUICK_STOP) else state
        elif not cw & 0x04:  # quick stop
            new = {OPERATION_ENABLED: QUICK_STOP, READY: SOD, SWITCHED_ON: SOD}.get(state, state)
        elif not cw & 0x01:  # shutdown
            new = READY if state in (SOD, SWITCHED_ON, OPERATION_ENABLED) else state
        elif not cw & 0x08:  # switch on, disable operation
            new = SWITCHED_ON if state in (READY, OPERATION_ENABLED) else state
        else:  # (switch on and) enable operation
            new = OPERATION_ENABLED if state in (READY, SWITCHED_ON, QUICK_STOP) else state
        self._enter(new)
        if self.state == OPERATION_ENABLED and self.mode == PP:
            if cw & CW_NEW_SET_POINT and not previous & CW_NEW_SET_POINT:
                self.target = self.target_position
                self._set_point_acknowledged = True
            elif not cw & CW_NEW_SET_POINT:
                self._set_point_acknowledged = False

    def _enter(self, state: str) -> None:
        if state == self.state:
            return
        leaving = self.state == OPERATION_ENABLED
        self.state = state
        if state == OPERATION_ENABLED:
            # A drive that is switched on holds where it is until it gets a target.
            self.target = self.position
            self._set_point_acknowledged = False
            self._profile = self._profile_generator()
        elif leaving:
            # Braked on the quick stop ramp (or switched off): the joint holds here.
            self.target = self.position

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

    # ------------------------------------------------------------------ PDOs

    def _on_rpdo(self, pdo: PdoMap) -> None:
        if self.node.nmt.state != "OPERATIONAL":
            return
        for var in pdo:
            data = bytes(var.get_data())
            if pdo.trans_type is not None and pdo.trans_type <= 240:
                with self._lock:
                    self._pending[(var.index, var.subindex)] = data
            else:
                self.node.set_data(var.index, var.subindex, data)

    def on_sync(self) -> None:
        with self._lock:
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
        for pdo in self.node.tpdo.map.values():
            if pdo.enabled:
                for var in pdo:
                    var.set_data(self.node.get_data(var.index, var.subindex))
                pdo.transmit()

    # ------------------------------------------------------------------ the joint

    def command(self) -> float:
        """Where the joint should go this control step (m or rad)."""
        joint = self.joint
        goal = joint.from_increments(self.target)
        if self.state == OPERATION_ENABLED and self.mode == PP:
            return goal if self._profile is None else self._profile.step(goal)
        return goal


class SimulatedDrives:
    """One simulated drive per configured joint, on a virtual CAN bus, moving a ``TableSim``.

    Args:
        config: the table configuration the master uses (node ids and calibration).
        sim: the simulated table; its rods must include every configured rod.
        rods_index: each rod's index in the simulator's joint arrays (slides of every rod,
            then spins); by default the order of ``sim.rods``.
        channel: the virtual channel; by default ``config.bus.channel``, for a config whose
            ``bus.interface`` is ``virtual``.

    Joints of the simulation without a drive (an opponent's rods) are held where they were
    when this was made, or wherever :meth:`set_free_targets` sends them.

    Attributes:
        drives: the simulated drives by node id.
        network: their ``canopen.Network``.
    """

    def __init__(
        self,
        config: TableConfig,
        sim: TableSim,
        rods_index: Mapping[str, int] | None = None,
        channel: str | int | None = None,
    ) -> None:
        if channel is None:
            if config.bus.interface != "virtual":
                raise ValueError(
                    "simulated drives are on python-can's virtual bus: pass channel=, or use "
                    f"a config whose bus.interface is 'virtual' (it is {config.bus.interface!r})"
                )
            channel = config.bus.channel
        if rods_index is None:
            rods_index = {rod.name: i for i, rod in enumerate(sim.rods)}
        missing = sorted({j.rod for j in config.joints} - set(rods_index))
        if missing:
            raise ValueError(f"rods {missing} have drives but are not in the simulation")
        self.sim = sim
        self.config = config
        self._n = len(rods_index)
        self._index = {
            (rod, kind): i + (self._n if kind == "spin" else 0)
            for rod, i in rods_index.items()
            for kind in ("slide", "spin")
        }
        positions, _ = sim.joint_states()
        self._targets = list(positions)
        self._lock = threading.RLock()
        self._flushed = threading.Event()
        self._flush_seq = 0
        self.network = canopen.Network()
        self.network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
        # The nodes hear their own frames too: that is how the flush marker comes back.
        self.network.connect(interface="virtual", channel=channel, receive_own_messages=True)
        self.drives: dict[int, SimulatedDrive] = {}
        try:
            for joint in config.joints:
                position = positions[self._index[joint.key]]
                drive = SimulatedDrive(joint, self._lock, position, sim.control_dt)
                self.network.add_node(drive.node)
                self.drives[joint.node_id] = drive
            self.network.subscribe(NMT_ID, self._on_nmt)
            self.network.subscribe(SYNC_ID, self._on_sync)
            self.network.subscribe(FLUSH_ID, self._on_flush)
            for drive in self.drives.values():
                drive.boot()
        except BaseException:
            self.network.disconnect()
            raise

    def __enter__(self) -> SimulatedDrives:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def drive(self, node_id: int) -> SimulatedDrive:
        try:
            return self.drives[node_id]
        except KeyError:
            raise KeyError(f"no simulated drive {node_id}; nodes: {sorted(self.drives)}") from None

    # ------------------------------------------------------------------ lockstep

    def apply(self) -> None:
        """Command the rods: each drive's target, or its hold position when not enabled.

        Waits first until the nodes have processed every frame sent before this call (a
        SYNC included), so the master's last targets are the ones applied.
        """
        self._flush()
        with self._lock:
            for drive in self.drives.values():
                self._targets[self._index[drive.joint.key]] = drive.command()
            targets = list(self._targets)
        self.sim.command("position", targets)

    def publish(self) -> None:
        """Store the rods' state in the nodes and send their TPDOs (after ``sim.step()``)."""
        positions, velocities = self.sim.joint_states()
        with self._lock:
            for drive in self.drives.values():
                i = self._index[drive.joint.key]
                drive.position = drive.joint.to_increments(positions[i])
                drive.velocity = drive.joint.speed_to_increments(velocities[i])
            for drive in self.drives.values():
                drive.send_tpdos()

    def set_free_targets(self, targets: Mapping[Joint, float]) -> None:
        """Targets (m or rad) for joints in the simulation that no drive moves (opponents)."""
        for key, value in targets.items():
            if key not in self._index:
                raise KeyError(f"{key} is not a joint of the simulation")
            if any(d.joint.key == key for d in self.drives.values()):
                raise ValueError(f"{key} is moved by its simulated drive")
            self._targets[self._index[key]] = float(value)

    # ------------------------------------------------------------------ faults for tests

    def inject_fault(self, node_id: int, code: int = 0x1000, *, emcy: bool = True) -> None:
        """Put a node into FAULT (statusword bit 3) and, by default, send an EMCY with ``code``."""
        self.drive(node_id).fault(code, emcy)

    def stop_heartbeat(self, node_id: int) -> None:
        """Silence a node's heartbeat, as a drive that lost power or its bus would."""
        self.drive(node_id).node.nmt.stop_heartbeat()

    def close(self) -> None:
        """Stop the nodes and close their bus; safe to call twice."""
        if self.network.bus is not None:
            self.network.disconnect()

    # ------------------------------------------------------------------ receive thread

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        for drive in self.drives.values():
            drive.on_nmt()

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        for drive in self.drives.values():
            drive.on_sync()

    def _on_flush(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if data[0] == self._flush_seq:
            self._flushed.set()

    def _flush(self) -> None:
        self._flush_seq = (self._flush_seq + 1) % 256
        self._flushed.clear()
        self.network.send_message(FLUSH_ID, bytes([self._flush_seq]))
        if not self._flushed.wait(FLUSH_TIMEOUT_S):
            raise RuntimeError(
                f"the simulated drives' bus did not process its frames within {FLUSH_TIMEOUT_S} s"
            )
