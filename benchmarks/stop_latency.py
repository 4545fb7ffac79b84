"""How fast the table stops when the master goes wrong, on the simulated drives (virtual bus).

Three figures, each over ``--trials`` trials, on a keeper table stepped at 60 Hz of the wall
clock while the master plays a fast swing:

- guard: a policy blocks for a second; from the last command a drive received to the quick
  stop the command guard sent it (watchdog_s = 50 ms);
- heartbeat: the master dies (its threads stop); from its last heartbeat to the drive's own
  quick stop (consumer heartbeat time = heartbeat_timeout_s = 100 ms, checked every step);
- brake then cut: a stop and close at full swing; from the quick stop to disable voltage, and
  the drive's speed when the power went off (0 = it had halted).

    python benchmarks/stop_latency.py [--trials 20]
"""

from __future__ import annotations

import argparse
import itertools
import logging
import threading
import time

import numpy as np

from foosball_gym.hardware import BusConfig, JointConfig, TableConfig
from foosball_gym.hardware.cia402.protocol import CW_DISABLE_VOLTAGE, CW_QUICK_STOP
from foosball_gym.hardware.drives import TableDrives
from foosball_gym.sim import TableSim
from foosball_gym.virtual_table import SimulatedDrives

SLIDE = ("home_keeper", "slide")
SPIN = ("home_keeper", "spin")
DT = 1 / 60
_channels = itertools.count()


def keeper_config() -> TableConfig:
    return TableConfig(
        joints=[
            JointConfig("home_keeper", "slide", 1, 100_000.0),
            JointConfig("home_keeper", "spin", 2, 1000.0, direction=-1),
        ],
        bus=BusConfig("virtual", f"stop-latency-{next(_channels)}", 1_000_000),
    )


class RealTimeTable:
    """The simulated keeper table, stepped at the control rate of the wall clock."""

    def __init__(self, config: TableConfig) -> None:
        self.sim = TableSim(["home_keeper"])
        self.sim.reset()
        self.sim_drives = SimulatedDrives(config, self.sim)
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

    def events(self, since: float, what: str, value: int | None = None) -> list:
        return [
            e
            for d in self.sim_drives.drives.values()
            for e in d.events
            if e.t > since and e.what == what and (value is None or e.value == value)
        ]

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self.sim_drives.close()
        self.sim.close()


def swing(drives: TableDrives, steps: int) -> None:
    for k in range(steps):
        side = 1.0 if (k // 6) % 2 == 0 else -1.0
        now = time.monotonic()
        drives.command({SLIDE: 0.1 * side, SPIN: 3.0 * side}, now)
        drives.feed_state(now)
        drives.check(now)
        time.sleep(DT)


def guard_latency(table: RealTimeTable, drives: TableDrives) -> list[float]:
    drives.bring_up()
    swing(drives, 9)
    blocked = time.monotonic()
    time.sleep(1.0)
    out = []
    for drive in table.sim_drives.drives.values():
        events = list(drive.events)
        last = max(e.t for e in events if e.what in ("rpdo", "sync") and e.t < blocked)
        stop = next(
            e for e in events if e.t > last and e.what == "controlword" and e.value == CW_QUICK_STOP
        )
        out.append(stop.t - last)
    return out


def heartbeat_latency(table: RealTimeTable, config: TableConfig) -> list[float]:
    drives = TableDrives(config)
    try:
        drives.bring_up()
        swing(drives, 9)
        drives.guard.stop()
        drives.heartbeat.stop()
        last_beat = drives.heartbeat._last
        time.sleep(0.3)
        return [e.t - last_beat for e in table.events(last_beat, "master heartbeat lost")]
    finally:
        drives.close()


def brake_then_cut(table: RealTimeTable, config: TableConfig) -> tuple[list[float], list[float]]:
    drives = TableDrives(config)
    with drives:
        drives.bring_up()
        swing(drives, 9)
        started = time.monotonic()
        drives.stop()
    time.sleep(0.05)
    stops = table.events(started, "controlword", CW_QUICK_STOP)
    cuts = table.events(started, "controlword", CW_DISABLE_VOLTAGE)
    first_stop = {e.t for e in stops}
    delays = [cut.t - min(first_stop) for cut in cuts]
    speeds = [e.speed for e in table.events(started, "power off")]
    return delays, speeds


def summary(name: str, values_s: list[float]) -> str:
    ms = 1e3 * np.array(values_s)
    return f"{name:34s} median {np.median(ms):7.1f} ms   max {ms.max():7.1f} ms   (n={ms.size})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    args = parser.parse_args()
    logging.getLogger("foosball_gym").setLevel(logging.CRITICAL)  # each guard trip logs
    config = keeper_config()
    table = RealTimeTable(config)
    try:
        guard: list[float] = []
        with TableDrives(config) as drives:
            for _ in range(args.trials):
                guard += guard_latency(table, drives)
        heartbeat: list[float] = []
        delays: list[float] = []
        speeds: list[float] = []
        for _ in range(args.trials):
            heartbeat += heartbeat_latency(table, config)
            d, s = brake_then_cut(table, config)
            delays += d
            speeds += s
    finally:
        table.close()
    print(summary("guard: last command -> quick stop", guard))
    print(summary("heartbeat: last beat -> own stop", heartbeat))
    print(summary("quick stop -> disable voltage", delays))
    print(f"{'speed at power off':34s} max {max(speeds):.0f} increments/s (n={len(speeds)})")


if __name__ == "__main__":
    main()
