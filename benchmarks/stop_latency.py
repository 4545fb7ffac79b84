"""How fast the table stops, and switches off, when its master goes wrong: on the simulated
drives (CiA 402 nodes on a virtual CAN bus), the wall clock, the table stepping at 60 Hz while
the master swings the keeper end to end.

Each case gives two times per drive: to its quick stop (the controlword, or the drive's own
stop on a lost heartbeat) and to its power stage going off, which it does itself once it has
braked to standstill (0x605A = 2); and the drive's speed when the power went (0 = it had
halted). The keeper table's configuration: watchdog_s 50 ms, heartbeat_timeout_s 100 ms.

- hung master: a policy (or a camera read) blocks; from the last command a drive received.
- master threads gone: the master's threads stop in its process; from its last heartbeat.
- frozen camera, play_real: the camera's ``read()`` gives its last frame again; from the
  last new picture (the loop goes on commanding meanwhile).
- frozen camera, play_sim: ``play_sim`` in real time, its camera process stopped (SIGSTOP);
  from the last picture, on the simulated table's watchdog (100 ms).
- frozen picture, play_sim: ``play_sim`` in real time, its camera giving its last picture
  again under fresh time stamps and no frame number, as a stalled USB camera does through
  ``OpenCVSource``; from the last new picture, on the simulated table's watchdog (100 ms).
- killed master: the master in a process of its own (the drives here, on a UDP multicast
  bus), sent SIGKILL, SIGSTOP or SIGTERM (which it handles, as ``foosball play`` does); from
  the signal.
- silent bus: the drives' frames lost (drives to master), or every frame (both ways); from
  the cut. Also in profile position mode (pp), where the loop's own SDO transfer hangs.
- stop and close: ``stop()`` then leaving the ``with`` block at full swing; from the stop.

    python benchmarks/stop_latency.py [--trials 10] [--only NAME]
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import logging
import os
import random
import signal
import subprocess
import sys
import textwrap
import threading
import time
from collections.abc import Callable

import numpy as np

from foosball_gym.real_table.hardware import (
    BusConfig,
    JointConfig,
    SafetyError,
    TableConfig,
    WatchdogTripped,
)
from foosball_gym.real_table.hardware.cia402.protocol import CW_QUICK_STOP
from foosball_gym.real_table.hardware.drives import TableDrives
from foosball_gym.real_table.virtual import SimulatedDrives
from foosball_gym.sim import TableSim

SLIDE = ("home_keeper", "slide")
SPIN = ("home_keeper", "spin")
DT = 1 / 60
_channels = itertools.count()

# Per trial and drive: (to quick stop, to power off, speed at power off), seconds and
# increments/s; None where a drive did not get there.
Times = list[tuple[float | None, float | None, float | None]]


def keeper_config(bus: BusConfig | None = None, mode: str = "csp") -> TableConfig:
    return TableConfig(
        joints=[
            JointConfig("home_keeper", "slide", 1, 100_000.0),
            JointConfig("home_keeper", "spin", 2, 1000.0, direction=-1),
        ],
        bus=bus or BusConfig("virtual", f"stop-latency-{next(_channels)}", 1_000_000),
        mode=mode,
    )


class RealTimeTable:
    """The simulated keeper table, stepped at the control rate of the wall clock."""

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

    def wait_until_off(self, timeout: float = 5.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(d.state == "SWITCH ON DISABLED" for d in self.sim_drives.drives.values()):
                return
            time.sleep(0.005)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sim_drives.close()
        self.sim.close()


def stop_times(drives: dict, since: float, stop: Callable[[object], bool] | None = None) -> Times:
    """Each drive's first stop after ``since`` and its power off, relative to ``since``."""
    stop = stop or is_stop
    out: Times = []
    for drive in drives.values():
        events = [e for e in drive.events if e.t > since]
        first = next((e for e in events if stop(e)), None)
        off = next((e for e in events if e.what == "power off"), None)
        out.append(
            (
                None if first is None else first.t - since,
                None if off is None else off.t - since,
                None if off is None else off.speed,
            )
        )
    return out


def is_stop(event) -> bool:
    return (
        event.what == "controlword" and event.value == CW_QUICK_STOP
    ) or event.what == "master heartbeat lost"


class TrialLost(Exception):
    """The master stopped before the fault was made (a loaded machine held it up for longer
    than its watchdog): the trial measures nothing, and is run again."""


@contextlib.contextmanager
def before_the_fault():
    try:
        yield
    except SafetyError as e:
        raise TrialLost(str(e)) from e


def swing(drives: TableDrives, steps: int, read: bool = False) -> None:
    for k in range(steps):
        side = 1.0 if (k // 6) % 2 == 0 else -1.0
        now = time.monotonic()
        drives.feed_state(now)
        drives.command({SLIDE: 0.1 * side, SPIN: 3.0 * side}, now)
        if read:
            drives.read()
        drives.check(now)
        time.sleep(DT)


# ---------------------------------------------------------------------------- the cases


def hung_master(table: RealTimeTable) -> Times:
    with TableDrives(table.config) as drives:
        with before_the_fault():
            drives.bring_up()
            swing(drives, 9)
        blocked = time.monotonic()
        table.wait_until_off()
        drive = next(iter(table.sim_drives.drives.values()))
        last = max(e.t for e in drive.events if e.what in ("rpdo", "sync") and e.t < blocked)
        times = stop_times(table.sim_drives.drives, last)
        with contextlib.suppress(WatchdogTripped):
            drives.command({}, time.monotonic())
    return times


def master_threads_gone(table: RealTimeTable) -> Times:
    drives = TableDrives(table.config)
    try:
        with before_the_fault():
            drives.bring_up()
            swing(drives, 9)
        drives.guard.stop()
        drives.heartbeat.stop()
        last_beat = drives.heartbeat._last
        table.wait_until_off()
        return stop_times(table.sim_drives.drives, last_beat)
    finally:
        with contextlib.suppress(Exception):
            drives.close()


def stop_and_close(table: RealTimeTable) -> Times:
    with TableDrives(table.config) as drives:
        with before_the_fault():
            drives.bring_up()
            swing(drives, 9)
        started = time.monotonic()
        drives.stop()
    table.wait_until_off()
    return stop_times(table.sim_drives.drives, started)


def frozen_camera_play_real(table: RealTimeTable) -> Times:
    from foosball_gym.camera import CameraModel
    from foosball_gym.real_table.play import stack
    from foosball_gym.real_table.vision import CameraCalibration
    from foosball_gym.registration import task_interface

    config = table.config
    model = CameraModel(160, 90)
    config.camera["calibration"] = CameraCalibration.from_camera_model(model).to_dict()
    picture = np.zeros((model.height, model.width, 3), np.uint8)
    given: list[float] = []

    class FrozenCamera:
        def __init__(self, *args: object) -> None:
            self.reads = 0

        def read(self) -> tuple[float, np.ndarray]:
            self.reads += 1
            if self.reads <= 30:
                given.append(time.monotonic())
            return given[-1], picture

        def close(self) -> None:
            pass

    real_source = stack.OpenCVSource
    stack.OpenCVSource = FrozenCamera  # type: ignore[misc, assignment]
    try:
        interface = task_interface("Foosball-Score-v0", {})
        try:
            stack.play_real(lambda obs: np.ones(2), interface, config, 10.0, status=False)
        except SafetyError as e:
            if getattr(e, "what", None) != "state estimate" or len(given) < 30:
                raise TrialLost(str(e)) from e
    finally:
        stack.OpenCVSource = real_source  # type: ignore[misc]
    table.wait_until_off()
    return stop_times(table.sim_drives.drives, given[-1])


def frozen_camera_play_sim(seed: int) -> Times:
    """``play_sim`` in real time; 40 loops in, the camera process is stopped."""
    from foosball_gym.real_table.play.stack import play_sim
    from foosball_gym.real_table.virtual import simulated_table
    from foosball_gym.real_table.virtual.camera_process import CameraProcess

    tables: list = []
    fed: list[float] = []
    real_init = simulated_table.SimulatedTable.__init__
    real_feed = TableDrives.feed_state
    real_close = CameraProcess.close

    def init(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        tables.append(self)

    def feed(self, now):
        fed.append(self.guard.clock())
        real_feed(self, now)

    def close(self):
        with contextlib.suppress(ProcessLookupError):
            os.kill(self._process.pid, signal.SIGCONT)
        real_close(self)

    calls = itertools.count()

    def policy(obs):
        k = next(calls)
        if k == 40:
            os.kill(tables[0]._camera._process.pid, signal.SIGSTOP)
        return np.array([1.0 if (k // 6) % 2 == 0 else -1.0])

    simulated_table.SimulatedTable.__init__ = init  # type: ignore[method-assign]
    TableDrives.feed_state = feed  # type: ignore[method-assign]
    CameraProcess.close = close  # type: ignore[method-assign]
    frozen: list[bool] = []
    try:
        play_sim(policy, "Foosball-Block-v0", {}, episodes=3, seed=seed, realtime=True)
    except SafetyError as e:
        frozen.append(getattr(e, "what", None) == "state estimate")
    finally:
        simulated_table.SimulatedTable.__init__ = real_init  # type: ignore[method-assign]
        TableDrives.feed_state = real_feed  # type: ignore[method-assign]
        CameraProcess.close = real_close  # type: ignore[method-assign]
    if frozen != [True]:
        raise TrialLost("the session stopped before the camera froze")
    return stop_times(tables[0].drives.drives, fed[-1])


def frozen_picture_play_sim(seed: int) -> Times:
    """``play_sim`` in real time; 40 loops in, the camera gives its last picture again."""
    from foosball_gym.real_table.play import stack
    from foosball_gym.real_table.virtual import simulated_table

    tables: list = []
    fed: list[float] = []
    real_init = simulated_table.SimulatedTable.__init__
    real_feed = TableDrives.feed_state
    real_camera = stack._TableCamera

    def init(self, *args, **kwargs):
        real_init(self, *args, **kwargs)
        tables.append(self)

    def feed(self, now):
        fed.append(self.guard.clock())
        real_feed(self, now)

    class StalledCamera(real_camera):  # type: ignore[misc, valid-type]
        reads = 0
        last = None

        def read(self):
            StalledCamera.reads += 1
            if StalledCamera.reads <= 40 or StalledCamera.last is None:
                t, picture = super().read()
                if picture is not None:
                    StalledCamera.last = picture
                self.frame_number = None  # as a camera that does not count its frames
                return t, picture
            return self.table.clock(), StalledCamera.last.copy()

    calls = itertools.count()

    def policy(obs):
        k = next(calls)
        return np.array([1.0 if (k // 6) % 2 == 0 else -1.0])

    simulated_table.SimulatedTable.__init__ = init  # type: ignore[method-assign]
    TableDrives.feed_state = feed  # type: ignore[method-assign]
    stack._TableCamera = StalledCamera  # type: ignore[misc]
    frozen: list[bool] = []
    try:
        stack.play_sim(policy, "Foosball-Block-v0", {}, episodes=3, seed=seed, realtime=True)
    except SafetyError as e:
        frozen.append("last picture again" in str(e))
    finally:
        simulated_table.SimulatedTable.__init__ = real_init  # type: ignore[method-assign]
        TableDrives.feed_state = real_feed  # type: ignore[method-assign]
        stack._TableCamera = real_camera  # type: ignore[misc]
    if frozen != [True]:
        raise TrialLost("the session stopped before the camera froze")
    return stop_times(tables[0].drives.drives, fed[-1])


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


def killed_master(sig: signal.Signals) -> Times:
    group = f"239.{random.randint(0, 255)}.{random.randint(0, 255)}.{random.randint(1, 254)}"
    port = random.randint(20_000, 60_000)
    table = RealTimeTable(
        keeper_config(), {"interface": "udp_multicast", "channel": group, "port": port}
    )
    master = subprocess.Popen(
        [sys.executable, "-c", MASTER, group, str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        if master.stdout is None or master.stdout.readline().strip() != "playing":
            raise TrialLost("the master stopped before it played")
        killed = time.monotonic()
        os.kill(master.pid, sig)
        table.wait_until_off()
        return stop_times(table.sim_drives.drives, killed)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.kill(master.pid, signal.SIGCONT)
            master.kill()
        master.wait(10)
        table.close()


def silent_bus(table: RealTimeTable, both_ways: bool) -> Times:
    drives = TableDrives(table.config)
    try:
        with before_the_fault():
            drives.bring_up()
            swing(drives, 9)
        cut = time.monotonic()
        table.sim_drives.cut_bus(outgoing=True, incoming=both_ways)
        with contextlib.suppress(SafetyError):
            swing(drives, 30, read=True)
        with contextlib.suppress(RuntimeError):
            drives.close()
        table.wait_until_off()
        return stop_times(table.sim_drives.drives, cut)
    finally:
        with contextlib.suppress(Exception):
            drives.close()


# ---------------------------------------------------------------------------- the report


def summary(name: str, times: Times) -> str:
    stops = 1e3 * np.array([s for s, _, _ in times if s is not None])
    offs = 1e3 * np.array([o for _, o, _ in times if o is not None])
    speeds = [v for _, _, v in times if v is not None]
    missing = sum(o is None for _, o, _ in times)

    def spread(ms: np.ndarray) -> str:
        if not ms.size:
            return "           none          "
        return f"{np.median(ms):6.1f} ({ms.min():5.1f}-{ms.max():5.1f})"

    left_on = f", {missing} left powered" if missing else ""
    return (
        f"{name:28s} stop {spread(stops)}  off {spread(offs)} ms  "
        f"speed at off max {max(speeds, default=0):.0f}  (n={len(times)}{left_on})"
    )


def fresh_table(case: Callable[[RealTimeTable], Times], mode: str = "csp") -> Callable[[], Times]:
    def run() -> Times:
        table = RealTimeTable(keeper_config(mode=mode))
        try:
            return case(table)
        finally:
            table.close()

    return run


CASES: dict[str, Callable[[int], Times]] = {
    "hung master": lambda k: fresh_table(hung_master)(),
    "master threads gone": lambda k: fresh_table(master_threads_gone)(),
    "frozen camera, play_real": lambda k: fresh_table(frozen_camera_play_real)(),
    "frozen camera, play_sim": frozen_camera_play_sim,
    "frozen picture, play_sim": frozen_picture_play_sim,
    "killed master, SIGKILL": lambda k: killed_master(signal.SIGKILL),
    "killed master, SIGSTOP": lambda k: killed_master(signal.SIGSTOP),
    "killed master, SIGTERM": lambda k: killed_master(signal.SIGTERM),
    "silent bus, drives to master": lambda k: fresh_table(lambda t: silent_bus(t, False))(),
    "silent bus, both ways": lambda k: fresh_table(lambda t: silent_bus(t, True))(),
    "silent bus, drives to master, pp": lambda k: fresh_table(
        lambda t: silent_bus(t, False), mode="pp"
    )(),
    "stop and close": lambda k: fresh_table(stop_and_close)(),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--only", choices=list(CASES), help="one case only")
    args = parser.parse_args()
    # Every stop logs; the figures are the point here.
    logging.getLogger("foosball_gym").setLevel(logging.CRITICAL)
    logging.getLogger("canopen").setLevel(logging.CRITICAL)
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for name, case in CASES.items():
        if args.only and name != args.only:
            continue
        times: Times = []
        lost = 0
        for k in range(3 * args.trials):
            if len(times) >= 2 * args.trials:  # two drives a trial
                break
            try:
                times += case(k)
            except TrialLost:
                lost += 1
        print(summary(name, times) + (f", {lost} trials lost" if lost else ""), flush=True)
    print(f"load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
