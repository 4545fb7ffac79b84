"""One drive's CANopen node as the master sees it: SDO access, and what it reports unasked.

:class:`DriveLink` takes one transfer with the drive at a time, turns the bus's and the SDO
client's errors into a :class:`DriveFault` that names the drive, and keeps what the bus's
receive thread hears from it (TPDOs, EMCY, heartbeat) under one condition, which the drive's
logic (:class:`~foosball_gym.real_table.hardware.cia402.drive.Cia402Drive`) waits on.
"""

from __future__ import annotations

import contextlib
import struct
import threading
import time
from collections.abc import Iterator

import can
import canopen
from canopen.emcy import EmcyError
from canopen.nmt import NmtError
from canopen.sdo.constants import EXPEDITED, REQUEST_DOWNLOAD, SIZE_SPECIFIED
from canopen.sdo.exceptions import SdoError

from foosball_gym.real_table.hardware.cia402.object_dictionary import object_dictionary
from foosball_gym.real_table.hardware.cia402.protocol import STATUSWORD
from foosball_gym.real_table.hardware.config import JointConfig
from foosball_gym.real_table.hardware.safety import DriveFault


class DriveLink:
    """The CANopen side of one drive: a ``canopen.RemoteNode`` added to ``network``.

    Args:
        network: the connected CANopen network the drive is on.
        joint: the joint it moves (its node id, and the name errors give).
    """

    def __init__(self, network: canopen.Network, joint: JointConfig) -> None:
        self.joint = joint
        # An SDO client serves one transfer at a time; a quick stop from the guard's thread
        # must also never land inside the play loop's set-point handshake, whose last write
        # would enable the drive again.
        self._lock = threading.RLock()
        self.node = canopen.RemoteNode(joint.node_id, object_dictionary(joint.node_id))
        network.add_node(self.node)
        self.network = network
        # What the receive thread reports; guarded by this condition's lock.
        self._changed = threading.Condition()
        self._statusword: int | None = None
        self._position: int | None = None
        self._velocity: int | None = None
        self._mode_display: int | None = None
        self._received = [0, 0]  # TPDO1, TPDO2 so far
        self._emcy: EmcyError | None = None
        self._heartbeat_at: float | None = None
        self._heartbeat_state: int | None = None
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

    def _send_unconfirmed(self, index: int, value: int) -> None:
        """An expedited SDO download of a 16-bit ``value`` to ``index``:0, sent past the SDO
        client (and its one transfer at a time) without waiting for the answer."""
        command = REQUEST_DOWNLOAD | EXPEDITED | SIZE_SPECIFIED | (2 << 2)  # 2 unused bytes
        request = struct.pack("<BHBH2x", command, index, 0, value)
        with self._talking(f"sending 0x{index:04X} = {value}"):
            self.network.send_message(self.node.sdo.rx_cobid, request)

    def _read_statusword(self) -> int:
        statusword = self._read(STATUSWORD)
        with self._changed:
            self._statusword = statusword
        return statusword
