"""The table stops safely when the master goes wrong: a loop that hangs, a master that dies,
and every stop braking to standstill before the power goes off.

The drives are the simulated C5-E look-alikes on python-can's virtual bus; the master is
:class:`~foosball_gym.real_table.hardware.drives.TableDrives`. Times come from the simulated drives'
event logs, on the table's clock. Latency figures: ``benchmarks/stop_latency.py``.
"""

from __future__ import annotations

import contextlib
import itertools
import threading
import time

import numpy as np
import pytest

from foosball_gym.real_table.hardware import (
    BusConfig,
    DriveFault,
    JointConfig,
    TableConfig,
    WatchdogTripped,
)
from foosball_gym.real_table.hardware.cia402.protocol import (
    ABORT_CONNECTION_OPTION_CODE,
    CONSUMER_HEARTBEAT_TIME,
    CW_DISABLE_VOLTAGE,
    CW_QUICK_STOP,
    DISABLE_OPERATION_OPTION_CODE,
    FAULT_REACTION_OPTION_CODE,
    OPERATION_ENABLED,
    PROFILE_DECELERATION,
    QUICK_STOP_DECELERATION,
    QUICK_STOP_OPTION_CODE,
    SHUTDOWN_OPTION_CODE,
    SW_TARGET_REACHED,
    state_name,
)
from foosball_gym.real_table.hardware.drives import DEFAULT_MASTER_NODE_ID, TableDrives
from foosball_gym.real_table.virtual import SimulatedDrives
from foosball_gym.real_table.virtual.drive_states import QUICK_STOP, SOD
from foosball_gym.sim import TableSim

SLIDE = ("home_keeper", "slide")
SPIN = ("home_keeper", "spin")
DT = 1 / 60
_channels = itertools.count()


def keeper_config(mode: str = "csp") -> TableConfig:
    return TableConfig(
        joints=[
            JointConfig("home_keeper", "slide", 1, 100_000.0),
            JointConfig("home_keeper", "spin", 2, 1000.0, direction=-1),
        ],
        bus=BusConfig("virtual", f"test-drive-safety-{next(_channels)}", 1_000_000),
        mode=mode,
    )


class RealTimeTable:
    """A simulated keeper table that steps itself at the control rate of the wall clock, as a
    real table moves whatever the master does; master and drives both on the wall clock."""

    def __init__(self, config: TableConfig) -> None:
        self.config = config
        self.sim = TableSim(["home_keeper"])
        self.sim.reset()
        self.sim_drives = SimulatedDrives(config, self.sim)
        self.drives = TableDrives(config)
        self.trace: list[tuple[float, list[float], list[float]]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        tick = time.monotonic()
        while not self._stop.is_set():
            self.sim_drives.apply()
            self.sim.step()
            self.sim_drives.publish()
            self.trace.append((time.monotonic(), *self.sim.joint_states()))
            tick += DT
            self._stop.wait(max(0.0, tick - time.monotonic()))

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.drives.close()
        self._stop.set()
        self._thread.join()
        self.sim_drives.close()
        self.sim.close()


@pytest.fixture
def realtime_table():
    made = []

    def make(mode: str = "csp") -> RealTimeTable:
        made.append(RealTimeTable(keeper_config(mode)))
        return made[-1]

    yield make
    for table in made:
        table.close()


def play(drives: TableDrives, steps: int, swing: bool = True) -> None:
    """``steps`` control steps at the control rate, the rods swinging end to end."""
    for k in range(steps):
        side = 1.0 if (k // 6) % 2 == 0 or not swing else -1.0
        drives.command({SLIDE: 0.1 * side, SPIN: 3.0 * side}, time.monotonic())
        drives.feed_state(time.monotonic())
        drives.check(time.monotonic())
        time.sleep(DT)


def quick_stops(events) -> list:
    """The quick stops a drive was sent, in order."""
    return [e for e in events if e.what == "controlword" and e.value == CW_QUICK_STOP]


def is_command(event) -> bool:
    """An event that carries a command of the play loop: a target (csp) or a set-point
    handshake (pp)."""
    return event.what in ("rpdo", "sync") or (
        event.what == "controlword" and event.value & 0x0F == 0x0F
    )


# ---------------------------------------------------------------------------- bring-up


def test_bring_up_sets_the_drives_to_watch_the_master_and_brake_on_every_stop():
    config = keeper_config()

    def bring_up_and_check() -> None:
        sim = TableSim(["home_keeper"])
        try:
            with SimulatedDrives(config, sim) as sim_drives, TableDrives(config) as drives:
                drives.bring_up()
                for drive in sim_drives.drives.values():
                    sdo = drive.node.sdo
                    joint = drive.joint
                    heartbeat = (DEFAULT_MASTER_NODE_ID << 16) | 100
                    assert sdo[CONSUMER_HEARTBEAT_TIME][1].raw == heartbeat
                    assert sdo[ABORT_CONNECTION_OPTION_CODE].raw == 3  # quick stop
                    assert sdo[QUICK_STOP_OPTION_CODE].raw == 2  # quick stop ramp, then off
                    assert sdo[SHUTDOWN_OPTION_CODE].raw == 1  # slow down, then switch off
                    assert sdo[DISABLE_OPERATION_OPTION_CODE].raw == 1
                    assert sdo[FAULT_REACTION_OPTION_CODE].raw == 2  # quick stop ramp
                    ramp = round(joint.max_acceleration * joint.increments_per_unit)
                    assert sdo[QUICK_STOP_DECELERATION].raw == sdo[PROFILE_DECELERATION].raw
                    assert sdo[QUICK_STOP_DECELERATION].raw == ramp
        finally:
            sim.close()

    # The simulated drives answer from a thread of this process: a loaded CI machine held
    # them past the SDO client's timeout (0.3 s, one retry) as the drives were stopped (once),
    # and the stop failed as it should. Once is the machine; twice in a row is the stack.
    try:
        bring_up_and_check()
    except RuntimeError as err:
        if "No SDO response received" not in str(err):
            raise
        bring_up_and_check()


# ---------------------------------------------------------------------------- a hung loop


@pytest.mark.parametrize("mode", ["csp", "pp"])
def test_a_policy_that_blocks_is_stopped_by_the_guard_within_the_watchdog_period(
    realtime_table, mode
):
    table = realtime_table(mode)
    drives = table.drives
    drives.bring_up()
    play(drives, 10)
    blocked_at = time.monotonic()
    time.sleep(1.0)  # the policy blocks for a second
    unblocked_at = time.monotonic()
    with pytest.raises(WatchdogTripped) as info:
        drives.command({SLIDE: 0.0}, time.monotonic())
    assert info.value.what == "command"
    for drive in table.sim_drives.drives.values():
        events = list(drive.events)
        last_command = max(e.t for e in events if is_command(e) and e.t < blocked_at)
        stops = quick_stops(events)
        assert stops, f"node {drive.joint.node_id} got no quick stop"
        stop = stops[0]
        # In order: the last command, the quick stop, then the loop wakes up; nothing in
        # between, and the stop within the 50 ms period (plus the guard's look).
        assert last_command < stop.t < unblocked_at
        assert stop.t - last_command <= 0.1
        assert not [e for e in events if last_command < e.t < stop.t and is_command(e)]
        assert stop.state == QUICK_STOP


def test_a_loop_that_stops_commanding_in_lock_step_is_stopped_by_the_guard(make_lockstep):
    table = make_lockstep()
    table.drives.bring_up()
    for _ in range(5):
        table.step({SLIDE: 0.05})
    for _ in range(4):  # the loop is stuck while the simulated table runs on
        table.advance()
        time.sleep(0.02)  # the guard's thread looks in between
    drives = table.sim_drives.drives.values()
    # A loaded machine may run the guard's thread late, or inside the last advance (whose
    # ramp then brings a slow rod to rest, and that drive switches off by itself).
    deadline = time.monotonic() + 2.0
    while any(d.state == OPERATION_ENABLED for d in drives) and time.monotonic() < deadline:
        time.sleep(0.005)
    for drive in drives:
        assert quick_stops(drive.events), f"node {drive.joint.node_id} got no quick stop"
        assert drive.state in (QUICK_STOP, SOD)
    with pytest.raises(WatchdogTripped):
        table.drives.command({SLIDE: 0.0}, table.now)


# ---------------------------------------------------------------------------- a dead master


class LockstepTable:
    """A simulated keeper table in lock-step whose drives and master both keep simulated time."""

    def __init__(self, config: TableConfig) -> None:
        self.config = config
        self.now = 0.0
        self.sim = TableSim(["home_keeper"])
        self.sim.reset()
        self.sim_drives = SimulatedDrives(config, self.sim, clock=self.clock)
        self.drives = TableDrives(config, clock=self.clock)

    def clock(self) -> float:
        return self.now

    def advance(self) -> None:
        self.now += DT
        self.sim_drives.apply()
        self.sim.step()
        self.sim_drives.publish()

    def step(self, targets: dict) -> None:
        self.now += DT
        self.drives.command(targets, self.now)
        self.sim_drives.apply()
        self.sim.step()
        self.sim_drives.publish()
        self.drives.read()
        self.drives.feed_state(self.now)
        self.drives.check(self.now)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.drives.close()
        self.sim_drives.close()
        self.sim.close()


@pytest.fixture
def make_lockstep():
    made = []

    def make(mode: str = "csp") -> LockstepTable:
        made.append(LockstepTable(keeper_config(mode)))
        return made[-1]

    yield make
    for table in made:
        table.close()


@pytest.mark.parametrize("death", ["threads gone", "bus gone"])
def test_a_killed_master_is_noticed_by_the_drives_which_brake_and_switch_off_on_their_own(
    make_lockstep, death
):
    table = make_lockstep()
    drives = table.drives
    drives.bring_up()
    for k in range(12):
        table.step({SLIDE: 0.1, SPIN: 6.0 if k < 6 else -6.0})
    killed_at = table.now
    if death == "threads gone":
        # What a killed process leaves: no thread of the master runs any more.
        drives.guard.stop()
        drives.heartbeat.stop()
    else:
        # The master's bus is gone: the guard cannot reach the drives either.
        drives.network.disconnect()
    trace = []
    for _ in range(60):
        table.advance()
        trace.append(table.sim.joint_states())
    timeout = table.config.heartbeat_timeout_s
    for drive in table.sim_drives.drives.values():
        lost = [e for e in drive.events if e.what == "master heartbeat lost"]
        assert [e.value for e in lost] == [DEFAULT_MASTER_NODE_ID]
        assert killed_at < lost[0].t <= killed_at + timeout + 2 * DT
        assert lost[0].state == QUICK_STOP
        # It braked to standstill, then switched its power stage off, by itself.
        after = [e for e in drive.events if e.t >= lost[0].t and e.what != "sync"]
        assert [e.what for e in after] == ["master heartbeat lost", "halted", "power off"]
        assert after[-1].speed == 0.0
        assert state_name(drive.statusword) == SOD
        # No command reached it after the master died; the quick stop was its own.
        assert not [e for e in drive.events if e.t > killed_at and e.what == "controlword"]
    positions = np.array([p for p, _ in trace])
    velocities = np.array([v for _, v in trace])
    np.testing.assert_allclose(velocities[-1], 0.0, atol=1e-3)
    np.testing.assert_allclose(positions[-20:], positions[-1:].repeat(20, 0), atol=1e-4)


# ---------------------------------------------------------------------------- brake, then cut


def _fault(table: RealTimeTable) -> type[BaseException]:
    table.sim_drives.inject_fault(2, 0x2310)
    play(table.drives, 5)
    return DriveFault


def _watchdog(table: RealTimeTable) -> type[BaseException]:
    drives = table.drives
    for _ in range(5):
        drives.command({SLIDE: -0.1, SPIN: -3.0}, time.monotonic())
        drives.check(time.monotonic())  # no state estimate any more
        time.sleep(DT)
    return WatchdogTripped


def _stop(table: RealTimeTable) -> None:
    table.drives.stop()


def _ctrl_c(table: RealTimeTable) -> type[BaseException]:
    raise KeyboardInterrupt


def swinging(realtime_table) -> RealTimeTable:
    """A table 150 ms into a swing, both rods moving fast. On the wall clock the suite's other
    worker can hold this process past the watchdog before the stop under test (it did once,
    99.4 ms against 50 ms), which stops the table as it should: then once more on a new table.
    Once is the machine; twice in a row is the stack."""

    def swing() -> RealTimeTable:
        table = realtime_table()
        table.drives.bring_up()
        play(table.drives, 9)
        return table

    try:
        return swing()
    except WatchdogTripped:
        return swing()


@pytest.mark.parametrize("cause", [_fault, _watchdog, _stop, _ctrl_c], ids=lambda f: f.__name__[1:])
def test_every_stop_brakes_to_standstill_before_the_power_goes_off(realtime_table, cause):
    table = swinging(realtime_table)
    drives = table.drives
    started = time.monotonic()
    with contextlib.suppress(DriveFault, WatchdogTripped, KeyboardInterrupt), drives:
        cause(table)
    time.sleep(0.3)  # the table moves on
    for drive in table.sim_drives.drives.values():
        events = [e for e in drive.events if e.t > started]
        cuts = [e for e in events if e.what == "controlword" and e.value == CW_DISABLE_VOLTAGE]
        power_off = [e for e in events if e.what == "power off"]
        assert power_off, f"node {drive.joint.node_id} was left powered"
        # The power went off once, at standstill: the drive had halted (and said so in its
        # statusword) before the master switched it off.
        assert [e.speed for e in power_off] == [0.0]
        for cut in cuts:
            assert state_name(cut.statusword) != QUICK_STOP or cut.statusword & SW_TARGET_REACHED
            assert cut.speed == 0.0
    # No rod coasts on after the stop.
    t, positions, velocities = zip(*table.trace)
    after = [i for i, ti in enumerate(t) if ti > t[-1] - 0.15]
    np.testing.assert_allclose(np.array(velocities)[after], 0.0, atol=1e-3)


def test_a_tripped_latch_is_reported_only_once_its_stop_has_been_sent():
    # The command guard trips the latch on its own thread; the play loop, checking meanwhile,
    # must not see the error (and go on to say the drives stopped) before the stop is out.
    from foosball_gym.real_table.hardware.safety import SafetyLatch

    stopping, release, sent = threading.Event(), threading.Event(), threading.Event()

    def stop_all(error):
        stopping.set()
        release.wait(5)
        sent.set()

    latch = SafetyLatch(stop_all)
    error = WatchdogTripped("command", 0.1, 0.05)

    def guard_trips():
        with contextlib.suppress(WatchdogTripped):
            latch.trip(error)

    guard = threading.Thread(target=guard_trips)
    guard.start()
    assert stopping.wait(5)
    seen = []

    def loop_checks():
        try:
            latch.check()
        except WatchdogTripped:
            seen.append(sent.is_set())

    loop = threading.Thread(target=loop_checks)
    loop.start()
    time.sleep(0.05)
    assert seen == []  # still waiting for the stop
    release.set()
    loop.join(5)
    guard.join(5)
    assert seen == [True]
