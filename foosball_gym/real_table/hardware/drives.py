"""All drives of a table behind the safety layer: what the play loop talks to.

.. code-block:: python

    with TableDrives(load_config(shipped_table("keeper"))) as drives:
        drives.bring_up()
        while playing:
            frame = camera.read()
            now = time.monotonic()
            if frame is new:
                drives.feed_state(now)     # news for the state estimate: a new camera frame
            ...                            # Kalman filter, policy
            drives.command(targets, now)   # checks faults and the watchdog first
            state = drives.read()          # {(rod, joint): (position, velocity)}
            drives.check(now)

Leaving the ``with`` block, normally or by any exception (Ctrl-C included), brakes every drive to
standstill, then switches it off, and re-raises. A fault on any drive, or a watchdog that trips,
quick-stops every drive and raises :class:`~foosball_gym.real_table.hardware.safety.DriveFault` or
:class:`~foosball_gym.real_table.hardware.safety.WatchdogTripped`; the table stays stopped, and
every later call raises the same error, until :meth:`TableDrives.bring_up` runs again. A quick stop
brakes on the drive's ramp and then switches its power stage off by itself (0x605A = 2, see
:mod:`~foosball_gym.real_table.hardware.cia402.bring_up`), so a stop ends unpowered even when nobody
is left to switch the drives off. Every drive is stopped at once, each from a thread of its own: one
that does not answer (a silent bus) delays none of the others.

Two supervisors do not depend on the loop calling in:

- the command guard (:class:`~foosball_gym.real_table.hardware.safety.CommandGuard`), a thread that
  quick-stops every drive when no command went out for ``watchdog_s`` on the table's clock,
  whatever the loop is doing (a policy that blocks, a camera read that hangs);
- the master's heartbeat (:class:`MasterHeartbeat`), sent from a thread of its own and with
  every command; each drive is set up to quick-stop itself when it misses it for
  ``heartbeat_timeout_s`` (objects 0x1016 and 0x6007), which covers a master that was killed,
  stopped (SIGSTOP), whose interpreter is stuck, or that lost the bus. Closing stops the
  drives' watch of it only on the drives that confirmed they are switched off: one that did
  not answer keeps watching, and stops itself once the heartbeat ends.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from types import TracebackType

import can
import canopen

from foosball_gym.real_table.hardware.cia402 import Cia402Drive
from foosball_gym.real_table.hardware.cia402.protocol import POWERED_STATES
from foosball_gym.real_table.hardware.config import Joint, TableConfig
from foosball_gym.real_table.hardware.safety import (
    CommandGuard,
    DriveFault,
    JointLimits,
    SafetyError,
    SafetyLatch,
    TargetLimiter,
    UnsafeCommand,
    Watchdog,
    WatchdogTripped,
)

logger = logging.getLogger(__name__)

# How long the receive thread may take to notice a closed network; the default (1 s) would
# make every close wait that long.
NOTIFIER_CYCLE_S = 0.1
# The master's node id when the configuration names none: the highest, which no drive of a
# table takes.
DEFAULT_MASTER_NODE_ID = 127
NMT_OPERATIONAL = 0x05
HEARTBEAT_BASE = 0x700


class MasterHeartbeat:
    """The master's CiA 301 heartbeat (COB-ID 0x700 + node id, state "operational").

    Sent from a thread every ``period_s`` of wall time (a producer heartbeat, 0x1017's job on
    a device) and by :meth:`beat` whenever the caller wants (every command): the drives watch
    it with their consumer heartbeat (0x1016). It lives as long as the master's process does;
    a kernel-side periodic send (socketcan's broadcast manager) would outlive a hung
    interpreter, which is exactly what the drives must notice.

    Args:
        network: the master's connected network.
        node_id: the master's node id.
        period_s: the longest gap between two beats.
    """

    def __init__(self, network: canopen.Network, node_id: int, period_s: float) -> None:
        if period_s <= 0:
            raise ValueError(f"the heartbeat period must be positive, got {period_s}")
        self.network = network
        self.node_id = node_id
        self.period_s = period_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._last = -float("inf")

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self) -> None:
        """Start beating (once; a stopped heartbeat stays stopped)."""
        if self._thread is None and not self._stop.is_set():
            self.beat()
            self._thread = threading.Thread(target=self._run, name="master-heartbeat", daemon=True)
            self._thread.start()

    def beat(self) -> None:
        """Send one beat now (nothing once stopped)."""
        if self._stop.is_set():
            return
        with self._lock:
            self._last = time.monotonic()
            self.network.send_message(HEARTBEAT_BASE + self.node_id, bytes([NMT_OPERATIONAL]))

    def stop(self) -> None:
        """Stop beating and wait for the thread; safe to call twice."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()

    def _run(self) -> None:
        poll = min(self.period_s / 4, 0.01)
        while not self._stop.wait(poll):
            if time.monotonic() - self._last < self.period_s - poll:
                continue
            try:
                self.beat()
            except (RuntimeError, can.CanError, OSError) as e:
                # The bus is gone: the drives will notice the silence, which is the point.
                logger.warning("master heartbeat stopped: %s", e)
                return


class TableDrives:
    """The table's drives, with limits, rate limits, a watchdog and one stop for all.

    Args:
        config: the table configuration. The master's node id is ``config.master_node_id``
            where the configuration has one, else :data:`DEFAULT_MASTER_NODE_ID`.
        network: a connected ``canopen.Network`` to use; by default one is opened on
            ``config.bus`` and closed by :meth:`close`.
        clock: the table's clock (seconds) the command guard measures the silence on: the
            wall clock for a real table or one simulated in real time, the simulated time in
            lock-step. :meth:`use_clock` changes it.
        answer_timeout_s: how long each drive's answer to a SYNC or a set-point may take
            (s); None: one control period, as a real table's drives give it. A table
            simulated in lock-step waits for the loop, so there a drive's answer held up by
            the machine's load is no fault.

    Attributes:
        drives: one :class:`Cia402Drive` per configured joint, by ``(rod, joint)``.
        watchdog: the :class:`Watchdog` fed by :meth:`command` and :meth:`feed_state`.
        guard: the :class:`CommandGuard`, fed by :meth:`command`.
        heartbeat: the :class:`MasterHeartbeat`, started by :meth:`bring_up`.
    """

    def __init__(
        self,
        config: TableConfig,
        network: canopen.Network | None = None,
        *,
        clock: Callable[[], float] = time.monotonic,
        answer_timeout_s: float | None = None,
    ) -> None:
        master_node_id = getattr(config, "master_node_id", DEFAULT_MASTER_NODE_ID)
        if master_node_id in {joint.node_id for joint in config.joints}:
            raise ValueError(f"the master's node id {master_node_id} is also a drive's")
        self.config = config
        self._own_network = network is None
        if network is None:
            network = canopen.Network()
            network.NOTIFIER_CYCLE = NOTIFIER_CYCLE_S
            bus = config.bus
            try:
                network.connect(interface=bus.interface, channel=bus.channel, bitrate=bus.bitrate)
            except Exception as err:  # noqa: BLE001 - each interface's library fails its own way
                # python-can's interfaces raise what their libraries do when a driver or a
                # module is missing (CanError, NameError, ...): an OSError, as one that cannot
                # open its device raises, is what a caller catches.
                raise OSError(
                    f"cannot open the CAN bus {bus.interface} {bus.channel!r}: "
                    f"{' '.join(str(err).split()) or type(err).__name__}"
                ) from err
        self.network = network
        self._closed = False
        try:
            self.drives: dict[Joint, Cia402Drive] = {
                joint.key: Cia402Drive(
                    network,
                    joint,
                    mode=config.mode,
                    control_hz=config.control_hz,
                    heartbeat_timeout_s=config.heartbeat_timeout_s,
                    master_node_id=master_node_id,
                    answer_timeout_s=answer_timeout_s,
                )
                for joint in config.joints
            }
        except BaseException:
            self._disconnect()
            raise
        self.heartbeat = MasterHeartbeat(network, master_node_id, config.heartbeat_timeout_s / 3)
        self.guard = CommandGuard(config.watchdog_s, self._on_silence, clock)
        self._limiters = {
            joint.key: TargetLimiter(JointLimits.of(joint), config.control_period)
            for joint in config.joints
        }
        self.watchdog = Watchdog(config.watchdog_s)
        self._latch = SafetyLatch(self._stop_for)
        self._running = False

    # ------------------------------------------------------------------ context manager

    def __enter__(self) -> TableDrives:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        try:
            self.close()
        except Exception:
            if exc is None:
                raise
            # The exception that ended the block is the one to see; this one goes to the log.
            logger.exception("while disabling the drives after %r", exc)

    # ------------------------------------------------------------------ the play loop's calls

    def bring_up(self) -> dict[Joint, float]:
        """Bring every drive to "operation enabled" and start from where the rods are.

        Clears a tripped safety latch and the watchdogs (a stopped table is restarted this
        way), and starts the master's heartbeat and the command guard, which arms on the first
        command. If a drive fails, the others are disabled again before the error is raised.

        Returns:
            Each joint's position (m or rad) at bring-up.
        """
        self._check_open()
        self._running = False
        self.guard.disarm()
        self._latch.reset()
        self.watchdog.reset()
        # Beating before the drives watch it: they start watching at the first beat they hear.
        self.heartbeat.start()
        self.guard.start()
        positions = {}
        try:
            for key, drive in self.drives.items():
                positions[key] = drive.bring_up()
                self._limiters[key].reset(positions[key])
        except BaseException:
            _, failures, _ = self._disable_all()
            if failures:
                logger.error("after a failed bring-up: %s", "; ".join(failures))
            raise
        self._running = True
        return positions

    def command(self, targets: Mapping[Joint, float], now: float) -> dict[Joint, float]:
        """Send one control step's position targets.

        Checks faults and the watchdog first, then limits and rate-limits every target and
        sends it; in csp one SYNC then makes all drives take theirs at once.

        Args:
            targets: SI targets (m or rad) by ``(rod, joint)``; a joint left out keeps going
                to its last target.
            now: the time of this command, on the clock :meth:`feed_state` and
                :meth:`check` use.

        Returns:
            The targets sent, after the safety layer.

        Raises:
            DriveFault, WatchdogTripped, UnsafeCommand: after every drive was stopped.
            RuntimeError: before :meth:`bring_up` or after :meth:`stop`.
        """
        self.check(now)
        if not self._running:
            raise RuntimeError("the drives are not running: call bring_up() first")
        unknown = [key for key in targets if key not in self._limiters]
        if unknown:
            self._latch.trip(
                UnsafeCommand(f"no drive for {unknown}; configured: {list(self._limiters)}")
            )
        sent = {}
        for key, limiter in self._limiters.items():
            try:
                sent[key] = limiter.step(targets.get(key))
            except ValueError as e:
                self._latch.trip(UnsafeCommand(f"{key[0]} {key[1]}: {e}"))
        try:
            for key, value in sent.items():
                self.drives[key].set_target(value)
            if self.config.mode == "csp":
                for drive in self.drives.values():
                    drive.mark_sync()
                self.network.sync.transmit()
        except DriveFault as e:
            self._latch.trip(e)
        # The guard's thread may have stopped the drives while these went out.
        self._latch.check()
        self.guard.feed()
        self.heartbeat.beat()
        self.watchdog.feed_command(now)
        return sent

    def read(self) -> dict[Joint, tuple[float, float]]:
        """Each joint's position and velocity (m, m/s or rad, rad/s).

        In csp right after :meth:`command`, the drives' answers to its SYNC (sampled at the
        same instant); otherwise read over SDO.
        """
        self._check_open()
        try:
            return {key: drive.actual() for key, drive in self.drives.items()}
        except DriveFault as e:
            self._latch.trip(e)

    def feed_state(self, now: float) -> None:
        """News for the state estimate arrived at ``now``: a new camera picture. Not every
        loop: a loop that only predicts, its camera delivering nothing, runs blind, and the
        watchdog stops the table ``watchdog_s`` after the last picture."""
        self.watchdog.feed_state(now)

    def check(self, now: float) -> None:
        """Raise if any drive is at fault or the watchdog trips, after stopping every drive.

        Raises:
            DriveFault: which node and why.
            WatchdogTripped: whether the command or the state estimate went stale.
        """
        self._check_open()
        self._latch.check()
        for drive in self.drives.values():
            reason = drive.fault_reason()
            if reason is not None:
                self._latch.trip(DriveFault(drive.joint, reason))
        if self._running:
            try:
                self.watchdog.check(now)
            except WatchdogTripped as e:
                self._latch.trip(e)

    def stop(self) -> None:
        """Quick-stop every drive (they brake, then switch off); :meth:`bring_up` starts them
        again."""
        self._check_open()
        self._quick_stop_all()

    def use_clock(self, clock: Callable[[], float]) -> None:
        """Let the command guard measure on the table's ``clock`` from now on."""
        self.guard.use_clock(clock)

    def close(self) -> None:
        """Brake every drive to standstill, switch it off, send it to NMT pre-operational, stop
        the master's heartbeat and close the bus.

        Every drive is tried, even when one fails or Ctrl-C arrives meanwhile; the failures
        are raised afterwards. A drive that did not confirm it is switched off is left
        watching the master's heartbeat, which ends here: it stops itself. Safe to call twice.
        """
        if self._closed:
            return
        self._closed = True
        self.guard.stop()
        off, failures, interrupt = self._disable_all()
        for key, drive in self.drives.items():
            if key not in off:
                logger.warning(
                    "%s: not confirmed switched off; it keeps watching the master's heartbeat, "
                    "and stops itself when that ends",
                    drive.joint.label,
                )
                continue
            try:
                drive.release()
            except Exception as e:  # every drive is tried, and the bus may be gone
                logger.warning("%s: %s", drive.joint.label, e)
        # The drives that are off stopped watching it in release().
        self.heartbeat.stop()
        self._disconnect()
        if interrupt is not None:
            raise interrupt
        if failures:
            raise RuntimeError("stopping the drives failed: " + "; ".join(failures))

    # ------------------------------------------------------------------ internals

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("the table's drives are closed")

    def _quick_stop_all(self) -> None:
        """Quick-stop every drive at once; raise afterwards if one did not confirm it."""
        self._running = False
        self.guard.disarm()
        failures, interrupt = self._for_every_drive(Cia402Drive.quick_stop)
        if interrupt is not None:
            raise interrupt
        if failures:
            raise RuntimeError("quick stop failed: " + "; ".join(failures))

    def _stop_for(self, error: SafetyError) -> None:
        self._quick_stop_all()

    def _on_silence(self, age: float) -> None:
        """The guard's thread: no command for longer than the watchdog allows."""
        if not self._running:
            return
        error = WatchdogTripped("command", age, self.guard.timeout)
        logger.error("%s: stopping every drive from the command guard", error)
        try:
            self._latch.trip(error)
        except SafetyError:
            pass  # the play loop raises it at its next call

    def _disable_all(self) -> tuple[set[Joint], list[str], KeyboardInterrupt | None]:
        """Quick-stop every drive at once, then switch each off as it reports standstill: they
        all brake together, so the wait is that of the slowest.

        Returns:
            The joints whose drive reported its power stage off, what failed, and a Ctrl-C
            that came meanwhile (every drive was tried all the same).
        """
        self._running = False
        self.guard.disarm()
        failures, interrupt = self._for_every_drive(Cia402Drive.quick_stop)
        states: dict[Joint, str] = {}

        def disable(drive: Cia402Drive) -> None:
            states[drive.joint.key] = drive.disable()

        more, second = self._for_every_drive(disable)
        off = {key for key, state in states.items() if state not in POWERED_STATES}
        return off, failures + more, interrupt or second

    def _for_every_drive(
        self, action: Callable[[Cia402Drive], object]
    ) -> tuple[list[str], KeyboardInterrupt | None]:
        """Run ``action`` on every drive at once, each in a thread of its own, and wait for all.

        A drive that does not answer waits out its SDO timeout in its own thread, never
        delaying the others; a Ctrl-C meanwhile does not leave one untried.

        Returns:
            What failed, one line per drive, and the Ctrl-C that came meanwhile, if one did.
        """
        failures: list[str] = []

        def run(drive: Cia402Drive) -> None:
            try:
                action(drive)
            except Exception as e:
                failures.append(str(e))

        threads = [
            threading.Thread(target=run, args=(drive,), name=f"drive-{key[0]}-{key[1]}")
            for key, drive in self.drives.items()
        ]
        for thread in threads:
            thread.start()
        interrupt = None
        for thread in threads:
            while thread.is_alive():
                try:
                    thread.join()
                except KeyboardInterrupt as e:
                    interrupt = e  # a second Ctrl-C must not leave the other drives running
        return failures, interrupt

    def _disconnect(self) -> None:
        if self._own_network and self.network.bus is not None:
            self.network.disconnect()
