"""Simulated drives: C5-E look-alikes on a virtual CAN bus that move the simulated rods.

:class:`SimulatedDrives` puts one :class:`~foosball_gym.real_table.virtual.drive.SimulatedDrive`
(a ``canopen.LocalNode``) per configured joint on a python-can ``virtual`` channel. Behind
them, each node's joint of a :class:`~foosball_gym.sim.TableSim` follows the node's target.

The caller steps the simulation; one control step in lockstep is:

1. the master sends (``TableDrives.command``: targets and, in csp, a SYNC),
2. :meth:`SimulatedDrives.apply` waits until the nodes have processed everything sent so
   far, then commands the rods,
3. the caller steps the simulation (``sim.step()``),
4. :meth:`SimulatedDrives.publish` stores the rods' positions and velocities in the nodes and
   sends their TPDOs,
5. the master reads (``TableDrives.read``: in csp it waits for those TPDOs).

Of the drives' modules, this is the only one that uses the simulator, and it only calls the
``TableSim`` it is given.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import can
import canopen

from foosball_gym.real_table.hardware.config import Joint, TableConfig
from foosball_gym.real_table.virtual.drive import SimulatedDrive

if TYPE_CHECKING:
    from foosball_gym.sim import TableSim

# A 29-bit frame the nodes' network sends to itself to learn that everything before it has
# been processed; CANopen devices use 11-bit identifiers only and never look at it.
FLUSH_ID = 0x1FFFFFFF
FLUSH_TIMEOUT_S = 1.0
NOTIFIER_CYCLE_S = 0.1
SYNC_ID = 0x80
NMT_ID = 0x000
HEARTBEAT_BASE = 0x700


class SimulatedDrives:
    """One simulated drive per configured joint, on a virtual CAN bus, moving a ``TableSim``.

    Args:
        config: the table configuration the master uses (node ids and calibration).
        sim: the simulated table; its rods must include every configured rod.
        rods_index: each rod's index in the simulator's joint arrays (slides of every rod,
            then spins); by default the order of ``sim.rods``.
        channel: the virtual channel; by default ``config.bus.channel``, for a config whose
            ``bus.interface`` is ``virtual``.
        bus_options: python-can's arguments for another bus than the virtual one
            (``interface``, ``channel``, ``port``, ...), one that a master in another process
            can reach (``udp_multicast``): a master that dies leaves these drives running.
        clock: the table's clock (s) the drives supervise the master's heartbeat on and stamp
            their events with: the wall clock for a table that runs in real time, the simulated
            time in lock-step.

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
        *,
        clock: Callable[[], float] = time.monotonic,
        bus_options: Mapping[str, Any] | None = None,
    ) -> None:
        if channel is None and bus_options is None:
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
        self.clock = clock
        self._watching: set[int] = set()
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
        self._muted = self._deaf = False
        if bus_options is None:
            # The nodes hear their own frames too: that is how the flush marker comes back.
            bus_options = {"interface": "virtual", "channel": channel, "receive_own_messages": True}
        self.network.connect(**bus_options)
        self._cut_into_the_bus()
        self.drives: dict[int, SimulatedDrive] = {}
        try:
            for joint in config.joints:
                position = positions[self._index[joint.key]]
                drive = SimulatedDrive(
                    joint, self._lock, position, sim.control_dt, clock, self._watch
                )
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
        """Command the rods: one control step of each drive's motion.

        Waits first until the nodes have processed every frame sent before this call (a
        SYNC included), so the master's last targets are the ones applied; then each drive
        checks the heartbeats it watches.
        """
        self._flush()
        for drive in self.drives.values():
            drive.supervise()
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

    def cut_bus(self, *, outgoing: bool = True, incoming: bool = False) -> None:
        """Lose every frame the drives send (``outgoing``: SDO answers, PDOs, heartbeats,
        EMCY), or every frame sent to them (``incoming``), or both, from now on: a broken
        wire or transceiver. The drives themselves go on, and still step their joints."""
        self._muted, self._deaf = outgoing, incoming

    def _cut_into_the_bus(self) -> None:
        """Route the nodes' frames through :meth:`cut_bus`'s switches (the flush marker, the
        simulation's own, always passes)."""
        bus, network = self.network.bus, self.network
        assert bus is not None  # connected above
        send, notify = bus.send, network.notify

        def guarded_send(msg: can.Message, timeout: float | None = None) -> None:
            if not self._muted or msg.arbitration_id == FLUSH_ID:
                send(msg, timeout)

        def guarded_notify(can_id: int, data: bytearray, timestamp: float) -> None:
            if not self._deaf or can_id == FLUSH_ID:
                notify(can_id, data, timestamp)

        # Instance attributes: the heartbeats' periodic sender and the receive thread's
        # listener look them up on these objects.
        bus.send = guarded_send  # type: ignore[method-assign]
        network.notify = guarded_notify  # type: ignore[method-assign]

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

    def _watch(self, node_id: int) -> None:
        """Listen for ``node_id``'s heartbeat (a drive was told to watch it)."""
        if node_id not in self._watching:
            self._watching.add(node_id)
            self.network.subscribe(HEARTBEAT_BASE + node_id, self._on_heartbeat)

    def _on_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        for drive in self.drives.values():
            drive.heard(can_id - HEARTBEAT_BASE)

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
