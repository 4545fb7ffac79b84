"""One CiA 402 drive on CANopen (a Nanotec C5-E in the paper's table), seen from the master.

:class:`Cia402Drive` brings one drive from whatever state it is in (a fault included) to "operation
enabled" in the configured mode, with the stop reactions of
:mod:`~foosball_gym.real_table.hardware.cia402.bring_up`; sends it targets in SI units, reads its
position and velocity back, stops it, and reports its faults: the statusword's fault bit, EMCY
messages and a lost or unexpected heartbeat, each with the node id and the reason.

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

import logging
import time

import canopen
from canopen.emcy import EmcyError
from canopen.nmt import NMT_STATES

from foosball_gym.real_table.hardware.cia402.bring_up import (
    lay_out_csp_pdos,
    mode_settings,
    stop_settings,
)
from foosball_gym.real_table.hardware.cia402.link import DriveLink
from foosball_gym.real_table.hardware.cia402.protocol import (
    CONSUMER_HEARTBEAT_TIME,
    CONTROLWORD,
    CW_CHANGE_IMMEDIATELY,
    CW_DISABLE_VOLTAGE,
    CW_ENABLE_OPERATION,
    CW_FAULT_RESET,
    CW_NEW_SET_POINT,
    CW_QUICK_STOP,
    CW_SHUTDOWN,
    CW_SWITCH_ON,
    DEVICE_PROFILE,
    DEVICE_TYPE,
    MODE_CODES,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    NMT_BOOT_UP,
    NMT_OPERATIONAL,
    OPERATION_ENABLED,
    POSITION_ACTUAL,
    SW_FAULT,
    SW_SET_POINT_ACKNOWLEDGE,
    SW_TARGET_REACHED,
    TARGET_POSITION,
    VELOCITY_ACTUAL,
    state_name,
)
from foosball_gym.real_table.hardware.config import JointConfig
from foosball_gym.real_table.hardware.safety import DriveFault

logger = logging.getLogger(__name__)

# The wait for standstill ends at this multiple of the ramp's length plus STOP_SLACK_S, whatever
# the drive reports.
STOP_TIME_FACTOR = 1.5
STOP_SLACK_S = 0.05


class Cia402Drive(DriveLink):
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
        answer_timeout_s: how long to wait for the drive's answer to a SYNC or a set-point
            (s); None: one control period, as a real drive gives it.

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
        answer_timeout_s: float | None = None,
    ) -> None:
        if mode not in MODE_CODES:
            raise ValueError(f"unknown drive mode {mode!r}; allowed: {', '.join(MODE_CODES)}")
        self.mode = mode
        self.control_hz = control_hz
        if answer_timeout_s is not None and not answer_timeout_s > 0:
            raise ValueError(f"answer_timeout_s must be positive or None, got {answer_timeout_s}")
        self.answer_timeout_s = 1.0 / control_hz if answer_timeout_s is None else answer_timeout_s
        self.heartbeat_timeout_s = heartbeat_timeout_s
        self.master_node_id = master_node_id
        super().__init__(network, joint)
        #: True from a finished bring-up to the next stop: a drive that leaves "operation
        #: enabled" in between is at fault.
        self.enabled = False
        self._pdo = False
        # Guarded by the receive condition's lock, as what the receive thread reports is.
        self._sync_mark: tuple[int, int] | None = None
        self._expect_nmt: int | None = None

    # ------------------------------------------------------------------ bring-up

    def bring_up(self) -> float:
        """Take the drive from any state to "operation enabled" in the configured mode.

        NMT pre-operational; check it is a CiA 402 device; fault reset or disable down to "switch on
        disabled"; heartbeats (its own, and watching the master's), the stop reactions and ramps
        (see :mod:`~foosball_gym.real_table.hardware.cia402.bring_up`), the mode's PDOs or profile;
        mode of operation, checked on its display; target = actual position, so it does not move;
        NMT operational (confirmed by its heartbeat); shutdown, switch on, enable operation.

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
        for index, subindex, value in stop_settings(
            joint, self.heartbeat_timeout_s, self.master_node_id
        ):
            self._write(index, value, subindex=subindex)
        if self.mode == "csp":
            self._map_pdos()
        for index, subindex, value in mode_settings(joint, self.mode, self.control_hz):
            self._write(index, value, subindex=subindex)
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

    def _map_pdos(self) -> None:
        lay_out_csp_pdos(self.node)
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
                state = "no heartbeat at all"
                if self._heartbeat_state is not None:
                    state = NMT_STATES.get(self._heartbeat_state, state)
                raise DriveFault(
                    self.joint,
                    f"no heartbeat reporting OPERATIONAL within "
                    f"{2 * self.heartbeat_timeout_s * 1e3:.0f} ms of the NMT command "
                    f"(last: {state})",
                )
            self._expect_nmt = NMT_OPERATIONAL

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
                    assert self._target is not None  # csp maps the PDOs in bring-up
                    self._target.raw = increments
                    self._rpdo.transmit()
                return
            base = CW_ENABLE_OPERATION | CW_CHANGE_IMMEDIATELY
            self._write(TARGET_POSITION, increments)
            self._write(CONTROLWORD, base | CW_NEW_SET_POINT)
            deadline = time.monotonic() + self.answer_timeout_s
            # Bit 4 must stay up until the drive has seen it; a fault ends the wait early and
            # is reported by fault_reason().
            while not (statusword := self._read_statusword()) & (
                SW_SET_POINT_ACKNOWLEDGE | SW_FAULT
            ):
                if time.monotonic() > deadline:
                    raise DriveFault(
                        self.joint,
                        f"did not acknowledge the set-point within "
                        f"{1e3 * self.answer_timeout_s:.1f} ms (statusword 0x{statusword:04X})",
                    )
            self._write(CONTROLWORD, base)

    def mark_sync(self) -> None:
        """Note that a SYNC is about to go out: :meth:`actual` waits for the answer to it."""
        with self._changed:
            self._sync_mark = (self._received[0], self._received[1])

    def actual(self) -> tuple[float, float]:
        """Position (m or rad) and velocity (m/s or rad/s).

        In csp after a SYNC: the drive's TPDO answer to it, waited for up to
        ``answer_timeout_s``. Otherwise (pp, or no SYNC since the last read): read over SDO.
        """
        joint = self.joint
        with self._changed:
            mark = self._sync_mark
            if self._pdo and mark is not None:
                answered = self._changed.wait_for(
                    lambda: self._received[0] > mark[0] and self._received[1] > mark[1],
                    timeout=self.answer_timeout_s,
                )
                if not answered:
                    raise DriveFault(
                        joint,
                        f"no TPDO answer to the SYNC within {1e3 * self.answer_timeout_s:.1f} ms",
                    )
                self._sync_mark = None
                # The drive's TPDOs answered, so both are set.
                assert self._position is not None and self._velocity is not None
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
        """Quick stop: the drive brakes on its quick stop ramp, then switches its power stage
        off by itself (0x605A = 2).

        A transfer of another thread's may hold the drive: one whose answer a silent bus lost
        waits out the SDO timeout (0.3 s). After one control period of waiting for it, the
        stop goes out at once as a bare SDO request (no answer awaited; an enable command
        that follows cannot take the drive out of the stop), and is sent again, confirmed,
        once the transfer has given up.
        """
        if not self._lock.acquire(timeout=1.0 / self.control_hz):
            self.enabled = False
            self._send_unconfirmed(CONTROLWORD, CW_QUICK_STOP)
            self._lock.acquire()
        try:
            self.enabled = False
            self._write(CONTROLWORD, CW_QUICK_STOP)
        finally:
            self._lock.release()

    @property
    def stop_time_s(self) -> float:
        """How long a quick stop from the joint's top speed takes on the configured ramp."""
        joint = self.joint
        # JointConfig fills in the defaults of those left None.
        assert joint.max_speed is not None and joint.max_acceleration is not None
        return joint.max_speed / joint.max_acceleration

    def wait_until_stopped(self) -> bool:
        """Wait until a quick-stopped drive reports standstill.

        Standstill: the drive left QUICK STOP ACTIVE by itself (it switches off once it has
        halted, 0x605A = 2; or a fault), or shows the statusword's target-reached bit there
        (halted, with an option code that holds). A velocity that reads near 0 is not taken
        for it: the drive's ramp may still run, and cutting the power then would let the rod
        coast. The wait is bounded by :data:`STOP_TIME_FACTOR` times :attr:`stop_time_s` plus
        :data:`STOP_SLACK_S`.

        Returns:
            True if the drive reported standstill, False if the bound passed first.
        """
        deadline = time.monotonic() + STOP_TIME_FACTOR * self.stop_time_s + STOP_SLACK_S
        while True:
            with self._lock:
                statusword = self._read_statusword()
                if state_name(statusword) != "QUICK STOP ACTIVE":
                    return True
                if statusword & SW_TARGET_REACHED:
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
            # A heartbeat confirmed the state expected.
            assert self._heartbeat_state is not None and self._heartbeat_at is not None
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
