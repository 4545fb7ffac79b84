"""Nothing is left powered and nothing goes silently wrong when the table's master cannot act:
a camera that stops delivering pictures, a loop that hangs, a master killed or stopped in a
process of its own, a CAN bus gone silent, a ``kill`` sent to ``foosball play``.

Every case ends the same way on the simulated drives: a quick stop, braking on the ramp, and
the power stage switched off at standstill (``"halted"``, then ``"power off"`` at speed 0,
the drive in SWITCH ON DISABLED). The tests assert that order and those final states, and
times only on a simulated clock; latencies on the wall clock are measured by
``benchmarks/stop_latency.py``.
"""

from __future__ import annotations

import contextlib
import itertools
import os
import random
import signal
import subprocess
import sys
import textwrap
import threading
import time

import can
import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("canopen")

from foosball_gym.real_table.hardware import (  # noqa: E402
    BusConfig,
    JointConfig,
    SafetyError,
    TableConfig,
    WatchdogTripped,
)
from foosball_gym.real_table.hardware.cia402.protocol import (  # noqa: E402
    CONSUMER_HEARTBEAT_TIME,
    CONTROLWORD,
    CW_QUICK_STOP,
)
from foosball_gym.real_table.hardware.drives import DEFAULT_MASTER_NODE_ID, TableDrives  # noqa: E402
from foosball_gym.real_table.play.stack import play_real, play_sim  # noqa: E402
from foosball_gym.real_table.play.termination import Terminated, stop_on_termination  # noqa: E402
from foosball_gym.real_table.virtual import (
    SimulatedDrives,  # noqa: E402
    simulated_table,  # noqa: E402
)
from foosball_gym.registration import task_interface  # noqa: E402
from foosball_gym.sim import TableSim  # noqa: E402

SLIDE = ("home_keeper", "slide")
SPIN = ("home_keeper", "spin")
DT = 1 / 60
OFF = "SWITCH ON DISABLED"
SMALL_CAMERA = (160, 90)
_channels = itertools.count()


def keeper_config(bus: BusConfig | None = None, mode: str = "csp") -> TableConfig:
    """The keeper's two drives, with the most lenient watchdog a table file allows and a
    2.5 times longer heartbeat time than the shipped table: these tests keep time on a shared
    machine, and assert the order of what happens, not how soon."""
    return TableConfig(
        joints=[
            JointConfig("home_keeper", "slide", 1, 100_000.0),
            JointConfig("home_keeper", "spin", 2, 1000.0, direction=-1),
        ],
        bus=bus or BusConfig("virtual", f"test-table-faults-{next(_channels)}", 1_000_000),
        mode=mode,
        watchdog_s=0.1,
        heartbeat_timeout_s=0.25,
    )


def swinging():
    """A policy that swings the keeper end to end, so a stop has something to brake."""
    steps = itertools.count()
    return lambda obs: np.array([1.0 if (next(steps) // 6) % 2 == 0 else -1.0], np.float32)


QUICK_STOP = f"controlword 0x{CW_QUICK_STOP:02X}"


def first_quick_stop(events) -> float:
    return next(e.t for e in events if e.what == "controlword" and e.value == CW_QUICK_STOP)


def assert_braked_then_off(events, first: str, since: float = -np.inf) -> None:
    """A drive's stop after ``since``: ``first`` set it off (SYNCs and targets left out, a
    repeated quick stop once: the master's way out quick-stops a stopped drive again); a
    drive that was moving braked on its ramp until it halted; the power went off once, at
    speed 0; what came after it (the master's stop commands, sent without knowing) changed
    nothing.
    """
    stops = [e for e in events if e.t > since and e.what not in ("sync", "rpdo")]
    names = [e.what if e.what != "controlword" else f"controlword 0x{e.value:02X}" for e in stops]
    names = [name for i, name in enumerate(names) if i == 0 or name != names[i - 1]]
    assert names and names[0] == first, names
    assert names.count("power off") == 1, names
    off = names.index("power off")
    (power_off,) = [e for e in stops if e.what == "power off"]
    after = [e for e in stops if e.t >= power_off.t and stops.index(e) > stops.index(power_off)]
    assert all(e.what == "controlword" and e.state == OFF for e in after), names
    assert power_off.speed == 0.0, f"the power went off at {power_off.speed} increments/s"
    if stops[0].speed > 0:
        assert "halted" in names[:off], names


class RealTimeTable:
    """The simulated keeper table stepping itself at the control rate of the wall clock, its
    drives on ``bus_options`` (the config's virtual bus by default)."""

    def __init__(self, config: TableConfig, bus_options: dict | None = None) -> None:
        self.config = config
        self.sim = TableSim(["home_keeper"])
        self.sim.reset()
        self.sim_drives = SimulatedDrives(config, self.sim, bus_options=bus_options)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        tick = time.monotonic()
        while not self._stop.is_set():
            self.sim_drives.apply()
            self.sim.step()
            self.sim_drives.publish()
            tick += DT
            self._stop.wait(max(0.0, tick - time.monotonic()))

    def wait_until_off(self, timeout: float = 10.0) -> None:
        """Until every drive has switched off (or ``timeout`` passed: the asserts tell)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(d.state == OFF for d in self.sim_drives.drives.values()):
                return
            time.sleep(0.01)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sim_drives.close()
        self.sim.close()


@pytest.fixture
def realtime_table():
    made = []

    def make(config: TableConfig | None = None, bus_options: dict | None = None):
        made.append(RealTimeTable(config or keeper_config(), bus_options))
        return made[-1]

    yield make
    for table in made:
        table.close()


def swing(drives: TableDrives, steps: int, read: bool = False) -> None:
    """``steps`` control steps at the control rate, the rods swinging end to end; ``read``
    waits for the drives' answer to each step's SYNC, as the play loop does."""
    for k in range(steps):
        side = 1.0 if (k // 6) % 2 == 0 else -1.0
        now = time.monotonic()
        drives.feed_state(now)
        drives.command({SLIDE: 0.1 * side, SPIN: 3.0 * side}, now)
        if read:
            drives.read()
        drives.check(now)
        time.sleep(DT)


def start_swinging(drives: TableDrives) -> None:
    """Bring the drives up and swing the rods for 9 steps. A machine too busy to keep the
    watchdog fed before the fault is made tests no fault: then the table is brought up again
    (which restarts a stopped one), up to three times."""
    for attempt in range(3):
        try:
            drives.bring_up()
            swing(drives, 9)
            return
        except SafetyError:
            if attempt == 2:
                raise


@pytest.fixture
def tables_seen(monkeypatch):
    """Each simulated table ``play_sim`` made, as it closed: per drive, its events, its state
    and the heartbeats it watched."""
    seen: list[dict] = []
    real_close = simulated_table.SimulatedTable.close

    def close(self):
        if hasattr(self, "drives"):
            seen.append(
                {
                    node: (list(d.events), d.state, dict(d._watched))
                    for node, d in self.drives.drives.items()
                }
            )
        real_close(self)

    monkeypatch.setattr(simulated_table.SimulatedTable, "close", close)
    return seen


# ---------------------------------------------------------------------------- a frozen camera


@pytest.mark.parametrize("frozen", ["no new frame", "the last picture again"])
def test_a_camera_that_stops_delivering_pictures_stops_the_table_within_the_watchdog(
    monkeypatch, tables_seen, frozen
):
    """The state watchdog hears of new pictures only: the loop goes on predicting, and
    commanding, but the table stops within ``watchdog_s`` and one control period of the last
    picture (on the simulated clock of a lock-step table), then brakes and switches off."""
    real_read = simulated_table.SimulatedTable.read
    reads, pictures = itertools.count(1), []

    def read(self):
        # 40 loops in the camera freezes, after a picture that is no serve's first: the
        # watchdog counts that one as come a camera's latency later (PlayLoop.new_ball).
        if next(reads) > 40 and pictures[-1][1] > self._served_at:
            t, picture = pictures[-1][1:]
            return t, (None if frozen == "no new frame" else picture)
        t, picture = real_read(self)
        if picture is not None:
            pictures.append((self.clock(), t, picture))
        return t, picture

    monkeypatch.setattr(simulated_table.SimulatedTable, "read", read)
    with pytest.raises(WatchdogTripped) as info:
        play_sim(swinging(), "Foosball-Block-v0", {}, episodes=5, camera_size=SMALL_CAMERA)
    assert info.value.what == "state estimate"
    config = simulated_table.virtual_table_config(task_interface("Foosball-Block-v0", {}))
    last_picture_at = pictures[-1][0]
    (drives,) = tables_seen
    for events, state, _ in drives.values():
        stop = next(e for e in events if e.what == "controlword" and e.value == CW_QUICK_STOP)
        assert last_picture_at < stop.t <= last_picture_at + config.watchdog_s + DT + 1e-9
        # Targets went on until the stop (the loop did not know), none after it.
        assert [e for e in events if e.what == "rpdo" and last_picture_at < e.t < stop.t]
        assert not [e for e in events if e.what == "rpdo" and e.t > stop.t]
        assert_braked_then_off(events, QUICK_STOP, stop.t - 1e-9)
        assert state == OFF


def test_the_wait_for_a_new_balls_second_frame_is_no_silence_of_the_camera():
    """The simulated table shows a serve's first frame at once and the next only after the
    camera's latency: with a latency longer than the watchdog (0.15 s against 0.1 s), every
    serve would trip it if the first frame counted as come early."""
    report = play_sim(
        swinging(),
        "Foosball-Block-v0",
        {},
        episodes=3,
        camera_size=(320, 180),  # large enough to find the ball in
        camera_latency_s=0.15,
    )
    assert report.episodes == 3
    # And the pictures came: the ball was measured in most loops, not only at each serve.
    assert len(report.ball_error_mm) > report.steps / 2


def test_play_real_stops_a_table_whose_camera_gives_the_same_frame_again(
    monkeypatch, realtime_table
):
    """``play_real`` with a camera whose ``read()`` returns its last frame again: the loop
    commands on, but the state watchdog stops the table, which brakes and switches off."""
    from foosball_gym.camera import CameraModel
    from foosball_gym.real_table.play import stack
    from foosball_gym.real_table.vision import CameraCalibration

    config = keeper_config()
    # The simulated drives answer a SYNC at their table's next step, up to 1/60 s later: a
    # slower loop leaves that wait (one period) room on a busy machine.
    config.control_hz = 40.0
    model = CameraModel(*SMALL_CAMERA)
    config.camera["calibration"] = CameraCalibration.from_camera_model(model).to_dict()
    table = realtime_table(config)
    picture = np.zeros((model.height, model.width, 3), np.uint8)
    given: list[float] = []

    class FrozenCamera:
        def __init__(self, *args):
            self.reads = 0

        def read(self):
            self.reads += 1
            if self.reads <= 30:
                given.append(time.monotonic())
            return given[-1], picture

        def close(self):
            pass

    monkeypatch.setattr(stack, "OpenCVSource", FrozenCamera)
    interface = task_interface("Foosball-Score-v0", {})
    with pytest.raises(WatchdogTripped) as info:
        play_real(lambda obs: np.array([1.0, 1.0]), interface, config, 10.0, status=False)
    assert info.value.what == "state estimate"
    table.wait_until_off()
    for drive in table.sim_drives.drives.values():
        events = list(drive.events)
        stop = next(e for e in events if e.what == "controlword" and e.value == CW_QUICK_STOP)
        assert given[-1] < stop.t
        assert not [e for e in events if e.what == "rpdo" and e.t > stop.t]
        assert_braked_then_off(events, QUICK_STOP, stop.t - 1e-9)
        assert drive.state == OFF


@pytest.mark.parametrize("counter", ["no frame counter", "a frame counter that stops"])
def test_a_camera_that_gives_its_last_picture_under_new_time_stamps_stops_the_table(
    monkeypatch, tables_seen, counter
):
    """A stalled camera or capture driver hands out its last picture again, stamped with the
    time it was read (as ``OpenCVSource`` stamps frames): newer time stamps are no new
    picture. Without a frame counter the loop sees the pixels unchanged; with one, the number
    standing still. The table stops within ``watchdog_s`` and one control period of the last
    new picture (on the simulated clock), then brakes and switches off."""
    from foosball_gym.real_table.play import stack

    pictures: list[float] = []

    class StalledCamera(stack._TableCamera):
        reads = 0

        def read(self):
            StalledCamera.reads += 1
            if StalledCamera.reads <= 40 or not pictures:
                t, picture = super().read()
                if picture is not None:
                    self.last = picture
                    pictures.append(self.table.clock())
                if counter == "no frame counter":
                    self.frame_number = None
                return t, picture
            # The last picture again, stamped as it is read, its number (if any) unchanged.
            return self.table.clock() + 1e-6, self.last.copy()

    monkeypatch.setattr(stack, "_TableCamera", StalledCamera)
    with pytest.raises(WatchdogTripped) as info:
        play_sim(swinging(), "Foosball-Block-v0", {}, episodes=5, camera_size=SMALL_CAMERA)
    assert info.value.what == "state estimate"
    assert "the camera gave its last picture again" in str(info.value)
    config = simulated_table.virtual_table_config(task_interface("Foosball-Block-v0", {}))
    (drives,) = tables_seen
    for events, state, _ in drives.values():
        stop = next(e for e in events if e.what == "controlword" and e.value == CW_QUICK_STOP)
        assert pictures[-1] < stop.t <= pictures[-1] + config.watchdog_s + DT + 1e-9
        assert [e for e in events if e.what == "rpdo" and pictures[-1] < e.t < stop.t]
        assert not [e for e in events if e.what == "rpdo" and e.t > stop.t]
        assert_braked_then_off(events, QUICK_STOP, stop.t - 1e-9)
        assert state == OFF


def test_a_still_table_seen_by_the_simulated_camera_is_no_frozen_camera():
    """A lock-step table whose rods and ball stand still (a resting ball, a keeper held in
    place) renders the same pixels frame after frame: its frames are numbered by the time
    they show, so the loop plays on to the end of the episode."""
    report = play_sim(
        lambda obs: np.zeros(2, np.float32),
        "Foosball-Score-v0",
        {"ball_start": "resting"},
        episodes=1,
        camera_size=SMALL_CAMERA,
        # No camera errors: a still scene renders byte for byte alike.
        camera_errors=False,
    )
    assert report.episodes == 1
    assert report.steps == gym.spec("Foosball-Score-v0").max_episode_steps


def test_a_video_file_of_a_still_scene_is_no_frozen_camera(tmp_path):
    """A video's frames are numbered by their place in the file: ten alike (a still scene)
    are ten new pictures for the watchdog, where a camera's ten alike would be one."""
    import cv2

    from foosball_gym.real_table.play.loop import PlayLoop
    from foosball_gym.real_table.vision import OpenCVSource

    path = str(tmp_path / "still.avi")
    writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 60, (160, 90))
    for _ in range(10):
        writer.write(np.full((90, 160, 3), 90, np.uint8))
    writer.release()

    class Drives:
        fed: list[float] = []

        def feed_state(self, now):
            self.fed.append(now)

        def command(self, targets, now):
            return targets

    source = OpenCVSource(path)
    drives = Drives()
    interface = task_interface("Foosball-Block-v0", {})
    loop = PlayLoop(lambda obs: obs, interface, drives, source, None, None, None)
    for _ in range(10):
        loop.hold({})
    source.close()
    assert len(drives.fed) == 10


def test_play_real_stops_a_table_whose_camera_gives_its_last_picture_under_new_time_stamps(
    monkeypatch, realtime_table
):
    """``play_real`` with a camera that, after 30 pictures, gives the last one again stamped
    with the time it is read (as ``OpenCVSource`` stamps a camera's frames): the loop commands
    on, but the state watchdog stops the table, which brakes and switches off."""
    from foosball_gym.camera import CameraModel
    from foosball_gym.real_table.play import stack
    from foosball_gym.real_table.vision import CameraCalibration

    config = keeper_config()
    config.control_hz = 40.0  # as in the test above: room for the drives' answer
    model = CameraModel(*SMALL_CAMERA)
    config.camera["calibration"] = CameraCalibration.from_camera_model(model).to_dict()
    table = realtime_table(config)
    rng = np.random.default_rng(0)
    given: list[float] = []

    class StalledCamera:
        def __init__(self, *args):
            self.picture = None

        def read(self):
            if len(given) < 30:
                # A sensor's noise: every real picture differs from the last somewhere.
                self.picture = rng.integers(0, 8, (model.height, model.width, 3), np.uint8)
                given.append(time.monotonic())
            return time.monotonic(), self.picture.copy()

        def close(self):
            pass

    monkeypatch.setattr(stack, "OpenCVSource", StalledCamera)
    interface = task_interface("Foosball-Score-v0", {})
    with pytest.raises(WatchdogTripped) as info:
        play_real(lambda obs: np.array([1.0, 1.0]), interface, config, 10.0, status=False)
    assert info.value.what == "state estimate"
    assert "the camera gave its last picture again" in str(info.value)
    assert len(given) == 30  # the fresh pictures kept it going
    table.wait_until_off()
    for drive in table.sim_drives.drives.values():
        events = list(drive.events)
        stop = next(e for e in events if e.what == "controlword" and e.value == CW_QUICK_STOP)
        assert given[-1] < stop.t
        assert not [e for e in events if e.what == "rpdo" and e.t > stop.t]
        assert_braked_then_off(events, QUICK_STOP, stop.t - 1e-9)
        assert drive.state == OFF


def test_the_real_time_tables_clock_never_runs_back(tables_seen):
    """The drives' events carry the table's clock: from the making of the table through the
    drives' switching on, the table's start and its stop. It ran back once when the table
    started (by however long the switching on took, a second on a loaded machine), so an event
    before the start could look as if it came after one that followed it."""
    play_sim(
        swinging(), "Foosball-Block-v0", {}, episodes=1, camera_size=SMALL_CAMERA, realtime=True
    )
    (drives,) = tables_seen
    for events, _, _ in drives.values():
        times = [e.t for e in events]
        assert times == sorted(times)
        assert [e.what for e in events][:3] == ["controlword"] * 3  # switched on first


def test_a_killed_camera_process_stops_the_table_with_one_error_and_no_traceback(
    monkeypatch, tables_seen, capfd
):
    """``play_sim`` in real time, its camera process killed: the table's clock thread and the
    loop both meet the closed pipe; the loop's read ends the session with an OSError that says
    so (one line from ``foosball play``), and the drives brake and switch off."""
    tables: list = []
    real_init = simulated_table.SimulatedTable.__init__

    def init(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        tables.append(self)

    monkeypatch.setattr(simulated_table.SimulatedTable, "__init__", init)
    calls = itertools.count()
    swing_policy = swinging()

    def policy(obs):
        if next(calls) == 40:
            process = tables[0]._camera._process
            os.kill(process.pid, signal.SIGKILL)
            process.join(timeout=10)
        return swing_policy(obs)

    # An OSError: foosball play's one line.
    with pytest.raises(OSError, match="camera process was killed by SIGKILL"):
        play_sim(
            policy, "Foosball-Block-v0", {}, episodes=5, camera_size=SMALL_CAMERA, realtime=True
        )
    assert "Traceback" not in capfd.readouterr().err
    (drives,) = tables_seen
    for events, state, _ in drives.values():
        assert_braked_then_off(events, QUICK_STOP, first_quick_stop(events) - 1e-9)
        assert state == OFF


class _ReapedElsewhere:
    """A killed process whose wait another thread won: its exit code shows a moment later."""

    def __init__(self, code: int, unseen_reads: int) -> None:
        self.code, self.unseen = code, unseen_reads

    def join(self, timeout: float | None = None) -> None:
        pass

    @property
    def exitcode(self) -> int | None:
        self.unseen -= 1
        return None if self.unseen >= 0 else self.code


def test_a_camera_process_reaped_by_another_thread_is_still_told_killed(monkeypatch):
    from foosball_gym.real_table.virtual import camera_process

    camera = camera_process.CameraProcess.__new__(camera_process.CameraProcess)  # no process
    camera._process = _ReapedElsewhere(-signal.SIGKILL, unseen_reads=3)
    assert "was killed by SIGKILL" in str(camera._gone())
    monkeypatch.setattr(camera_process, "GONE_WAIT_S", 0.05)  # the fake's join does not wait
    camera._process = _ReapedElsewhere(0, unseen_reads=10**9)  # never ends
    assert "is still there but its pipe is closed" in str(camera._gone())


# ---------------------------------------------------------------------------- a hung master


def test_a_loop_that_hangs_is_stopped_by_the_guard_and_the_drives_end_switched_off(
    realtime_table,
):
    """A policy or a camera read that never returns: no command goes out, the command guard
    quick-stops every drive, and each brakes and switches its power off, the loop still
    hanging."""
    table = realtime_table()
    with TableDrives(table.config) as drives:
        start_swinging(drives)
        hung_at = time.monotonic()
        table.wait_until_off()  # the loop hangs meanwhile
        for drive in table.sim_drives.drives.values():
            assert_braked_then_off(drive.events, QUICK_STOP, hung_at)
            assert drive.state == OFF
        with pytest.raises(WatchdogTripped):  # the loop wakes up to the stop
            drives.command({SLIDE: 0.0}, time.monotonic())


@pytest.mark.slow
def test_a_camera_read_that_hangs_in_play_ends_with_the_drives_switched_off(
    monkeypatch, tables_seen
):
    """The probe's case on the simulated table in real time: the camera's read never returns;
    the drives end switched off while it still hangs."""
    real_read = simulated_table.SimulatedTable.read
    reads = itertools.count(1)
    states_while_hung: list[dict] = []

    def read(self):
        if next(reads) == 60:
            # Hung, until every drive is off (or 10 s passed); what they did is taken then.
            deadline = time.monotonic() + 10
            while time.monotonic() < deadline:
                if all(d.state == OFF for d in self.drives.drives.values()):
                    break
                time.sleep(0.01)
            states_while_hung.append({n: d.state for n, d in self.drives.drives.items()})
        return real_read(self)

    monkeypatch.setattr(simulated_table.SimulatedTable, "read", read)
    with pytest.raises(WatchdogTripped) as info:
        play_sim(
            swinging(),
            "Foosball-Block-v0",
            {},
            episodes=3,
            camera_size=SMALL_CAMERA,
            realtime=True,
        )
    assert info.value.what == "command"
    assert states_while_hung == [{1: OFF, 2: OFF}]
    for events, _, _ in tables_seen[0].values():
        assert_braked_then_off(events, QUICK_STOP, first_quick_stop(events) - 1e-9)


# ---------------------------------------------------------------------------- a killed master

MASTER = textwrap.dedent(
    """
    import sys, time
    import canopen
    from foosball_gym.real_table.hardware import BusConfig, JointConfig, TableConfig
    from foosball_gym.real_table.hardware.drives import TableDrives
    from foosball_gym.real_table.play.termination import Terminated, catch_termination

    group, port = sys.argv[1], int(sys.argv[2])
    config = TableConfig(
        joints=[
            JointConfig("home_keeper", "slide", 1, 100_000.0),
            JointConfig("home_keeper", "spin", 2, 1000.0, direction=-1),
        ],
        bus=BusConfig("virtual", "unused"),
        # The most a table file allows: this master keeps time on a shared machine.
        watchdog_s=0.1,
        heartbeat_timeout_s=0.25,
    )
    network = canopen.Network()
    network.connect(interface="udp_multicast", channel=group, port=port)
    catch_termination()  # as foosball play does
    try:
        with TableDrives(config, network=network) as drives:
            drives.bring_up()
            for k in range(10**9):
                side = 1.0 if (k // 6) % 2 == 0 else -1.0
                now = time.monotonic()
                drives.feed_state(now)
                drives.command({("home_keeper", "slide"): 0.1 * side,
                                ("home_keeper", "spin"): 3.0 * side}, now)
                drives.check(now)
                if k == 20:
                    print("playing", flush=True)
                time.sleep(1 / 60)
    except Terminated as e:
        sys.exit(128 + e.signum)
    """
)


@pytest.fixture
def master_elsewhere(realtime_table):
    """Simulated drives here, on a UDP multicast bus of their own, and their master in a
    process of its own (the test's), playing a swing until it is killed."""
    group = f"239.{random.randint(0, 255)}.{random.randint(0, 255)}.{random.randint(1, 254)}"
    port = random.randint(20_000, 60_000)
    bus = {"interface": "udp_multicast", "channel": group, "port": port}
    table = realtime_table(keeper_config(), bus)
    # A master held up past its watchdog by a busy machine stops before it plays: that is
    # no kill to test, and it is started again (the next bring-up resets the drives).
    for _ in range(3):
        master = subprocess.Popen(
            [sys.executable, "-c", MASTER, group, str(port)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert master.stdout is not None and master.stderr is not None
        if master.stdout.readline().strip() == "playing":
            break
        master.wait(10)
    else:
        pytest.fail(f"the master did not play: {master.stderr.read()}")
    try:
        yield table, master
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(master.pid, signal.SIGCONT)
            master.kill()
        master.wait(10)


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGSTOP], ids=lambda s: s.name)
def test_a_master_killed_or_stopped_leaves_every_drive_switched_off_by_itself(
    master_elsewhere, sig
):
    table, master = master_elsewhere
    killed_at = time.monotonic()
    os.kill(master.pid, sig)
    table.wait_until_off()
    for drive in table.sim_drives.drives.values():
        # Nothing of the master came after it died; the drive noticed its heartbeat missing,
        # braked to standstill and switched itself off.
        assert not [e for e in drive.events if e.t > killed_at and e.what == "controlword"]
        assert_braked_then_off(drive.events, "master heartbeat lost", killed_at)
        lost = next(e for e in drive.events if e.what == "master heartbeat lost")
        assert lost.value == DEFAULT_MASTER_NODE_ID
        assert drive.state == OFF


def test_a_master_sent_sigterm_stops_its_drives_itself_and_exits_non_zero(master_elsewhere):
    table, master = master_elsewhere
    killed_at = time.monotonic()
    os.kill(master.pid, signal.SIGTERM)
    assert master.wait(20) == 128 + signal.SIGTERM, master.stderr.read()
    for drive in table.sim_drives.drives.values():
        # The master braked and switched every drive off on its way out, then released its
        # watch: no heartbeat went missing.
        assert_braked_then_off(drive.events, QUICK_STOP, killed_at)
        assert drive.state == OFF
        assert not drive._watched


# ---------------------------------------------------------------------------- a silent bus


class BusSpy:
    """Every frame on a virtual channel, in the order the bus carried them."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.frames: list[can.Message] = []
        self.notifier = can.Notifier(self.bus, [self.frames.append], timeout=0.01)

    def sdo_requests(self, since: int = 0) -> list[tuple[int, int, int, int]]:
        """(node, command, index, value) of each SDO request from the master."""
        out = []
        for msg in self.frames[since:]:
            if 0x601 <= msg.arbitration_id <= 0x67F:
                data = bytes(msg.data)
                index = int.from_bytes(data[1:3], "little")
                value = int.from_bytes(data[4:8], "little")
                out.append((msg.arbitration_id - 0x600, data[0], index, value))
        return out

    def close(self) -> None:
        self.notifier.stop()
        self.bus.shutdown()


SDO_ABORT = 0x80
SDO_WRITE_2_BYTES = 0x2B


@pytest.mark.parametrize(
    "silent, mode", [("drives to master", "csp"), ("both ways", "csp"), ("drives to master", "pp")]
)
def test_a_silent_bus_stops_every_drive_at_once_and_leaves_it_switched_off(
    realtime_table, silent, mode
):
    """csp: the drives' answer to a SYNC does not come, and the master stops them all at once.
    pp: the loop waits out an SDO timeout inside a drive's set-point handshake; the command
    guard stops every drive meanwhile, that one by a bare SDO request past the hung transfer.
    Both ways silent: the drives hear nothing of the master and stop themselves."""
    table = realtime_table(keeper_config(mode=mode))
    spy = BusSpy(table.config.bus.channel)
    drives = TableDrives(table.config)
    try:
        start_swinging(drives)
        cut_at, first_frame = time.monotonic(), len(spy.frames)
        table.sim_drives.cut_bus(outgoing=True, incoming=silent == "both ways")
        with pytest.raises(SafetyError):  # no answer within a control period, or at all
            swing(drives, 5, read=True)
        with contextlib.suppress(RuntimeError):  # no drive confirms its stop
            drives.close()
        table.wait_until_off()
    finally:
        spy.close()
        with contextlib.suppress(RuntimeError):
            drives.close()
    requests = spy.sdo_requests(first_frame)
    stops = [
        i
        for i, (_, cmd, index, value) in enumerate(requests)
        if index == CONTROLWORD and cmd == SDO_WRITE_2_BYTES and value == CW_QUICK_STOP
    ]
    aborts = [i for i, (_, cmd, _, _) in enumerate(requests) if cmd == SDO_ABORT]
    # The quick stop went to every drive before the master gave up waiting on any of them:
    # all at once, not one SDO timeout after another.
    assert sorted({requests[i][0] for i in stops[:2]}) == [1, 2]
    assert aborts and max(stops[:2]) < min(aborts)
    # Nothing told a drive to stop watching the master's heartbeat.
    assert not [r for r in requests if r[2] == CONSUMER_HEARTBEAT_TIME]
    for drive in table.sim_drives.drives.values():
        assert drive._watched, "the drive no longer watches the master's heartbeat"
        first = "master heartbeat lost" if silent == "both ways" else (QUICK_STOP)
        assert_braked_then_off(drive.events, first, cut_at)
        assert drive.state == OFF


# ---------------------------------------------------------------------------- foosball play


def test_sigterm_to_play_brakes_and_switches_the_drives_off_then_raises(tables_seen):
    calls = itertools.count()
    swing_policy = swinging()

    def policy(obs):
        if next(calls) == 30:
            os.kill(os.getpid(), signal.SIGTERM)
        return swing_policy(obs)

    with pytest.raises(Terminated) as info, stop_on_termination():
        play_sim(policy, "Foosball-Block-v0", {}, episodes=5, camera_size=SMALL_CAMERA)
    assert info.value.signum == signal.SIGTERM
    (drives,) = tables_seen
    for events, state, watched in drives.values():
        assert_braked_then_off(events, QUICK_STOP, first_quick_stop(events) - 1e-9)
        assert state == OFF and not watched


def test_foosball_play_exits_on_sigterm_with_a_line_and_no_traceback(tmp_path):
    log = tmp_path / "session.jsonl"
    play = subprocess.Popen(
        [
            sys.executable,
            # A session that does not end dumps its threads' stacks on SIGABRT (below).
            "-X",
            "faulthandler",
            "-m",
            "foosball_gym.cli",
            "play",
            "scripted",
            "--env",
            "Foosball-Block-v0",
            "--table",
            "sim",
            "--lockstep",
            "--episodes",
            "1000",
            "--camera",
            "160x90",
            "--no-status",
            "--log",
            str(log),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and play.poll() is None:
            if log.exists() and len(log.read_text().splitlines()) > 20:
                break
            time.sleep(0.1)
        play.send_signal(signal.SIGTERM)
        try:
            out, err = play.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            play.send_signal(signal.SIGABRT)
            _, err = play.communicate(timeout=30)
            pytest.fail(f"foosball play ran on 60 s after SIGTERM; where it was:\n{err[-6000:]}")
    finally:
        play.kill()
    assert play.returncode == 128 + signal.SIGTERM, err
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1] == "stopped: terminated by SIGTERM"


class FakeFrame:
    """A frame of the file ``filename``, as a signal handler is given it."""

    def __init__(self, filename: str) -> None:
        self.f_code = type("Code", (), {"co_filename": filename})()


def test_a_sigterm_landing_in_threading_code_is_taken_up_once_the_thread_is_out_of_it():
    import threading

    from foosball_gym.real_table.play.termination import catch_termination

    restore = catch_termination()
    try:
        handler = signal.getsignal(signal.SIGTERM)
        # Entering a lock-guarded block: raising here would leave the lock held for good.
        handler(signal.SIGTERM, FakeFrame(threading.__file__))
        assert signal.getitimer(signal.ITIMER_REAL)[0] > 0, "taken up again soon"
        with pytest.raises(Terminated) as info:
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline:
                time.sleep(0.001)  # out of threading's code: the held signal lands here
        assert info.value.signum == signal.SIGTERM
        # Told once: the next SIGTERM is ignored while the drives stop.
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        restore()


def test_a_sigterm_is_held_out_of_threading_code_only_so_long(monkeypatch):
    import threading

    from foosball_gym.real_table.play import termination

    monkeypatch.setattr(termination, "HOLD_LIMIT_S", 0.0)
    restore = termination.catch_termination()
    try:
        handler = signal.getsignal(signal.SIGTERM)
        with pytest.raises(Terminated):
            handler(signal.SIGTERM, FakeFrame(threading.__file__))
        assert signal.getitimer(signal.ITIMER_REAL)[0] == 0
    finally:
        restore()
