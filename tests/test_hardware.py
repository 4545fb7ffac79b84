"""The real-table driver: configuration, safety layer, CANopen drives against simulated ones.

The drives are ``canopen.LocalNode`` look-alikes of the C5-E on python-can's virtual bus, each
moving a joint of a real ``TableSim``; every test uses its own channel.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
import time

import numpy as np
import pytest

from foosball_gym.real_table.hardware import (
    BusConfig,
    ConfigError,
    DriveFault,
    JointConfig,
    TableConfig,
    UnsafeCommand,
    WatchdogTripped,
    load_config,
    save_config,
    shipped_table,
)
from foosball_gym.real_table.hardware.cia402.protocol import (
    CW_QUICK_STOP,
    OPERATION_ENABLED,
    state_name,
)
from foosball_gym.real_table.hardware.drives import TableDrives
from foosball_gym.real_table.hardware.safety import JointLimits, TargetLimiter, Watchdog
from foosball_gym.real_table.virtual import SimulatedDrives
from foosball_gym.sim import TableSim
from foosball_gym.table import SLIDE_MAX_SPEED, SPIN_LIMIT, SPIN_MAX_SPEED, rod

SLIDE = ("home_keeper", "slide")
SPIN = ("home_keeper", "spin")
DT = 1 / 60
_channels = itertools.count()


def keeper_config(mode: str = "csp", **joint_overrides: dict) -> TableConfig:
    """The keeper on a fresh virtual channel; the spin drive counts the other way round."""
    slide = dict(rod="home_keeper", joint="slide", node_id=1, increments_per_unit=100_000.0)
    spin = dict(
        rod="home_keeper", joint="spin", node_id=2, increments_per_unit=1000.0, direction=-1
    )
    slide.update(joint_overrides.get("slide", {}))
    spin.update(joint_overrides.get("spin", {}))
    return TableConfig(
        joints=[JointConfig(**slide), JointConfig(**spin)],
        bus=BusConfig("virtual", f"test-hardware-{next(_channels)}", 1_000_000),
        mode=mode,
    )


class Table:
    """A simulated keeper table, its simulated drives and the master's drives, in lockstep.

    The master's command guard runs on the simulated time (the world waits for the loop);
    the drives watch the master's heartbeat on the wall clock unless ``drive_clock`` says
    "simulated".
    """

    def __init__(self, config: TableConfig, drive_clock: str = "wall") -> None:
        self.config = config
        self.now = 0.0
        self.sim = TableSim(["home_keeper"])
        self.sim.reset()
        clock = {"wall": time.monotonic, "simulated": self.clock}[drive_clock]
        self.sim_drives = SimulatedDrives(config, self.sim, clock=clock)
        self.drives = TableDrives(config, clock=self.clock)

    def clock(self) -> float:
        return self.now

    def advance(self) -> None:
        """One control step of the table alone, the master sending nothing."""
        self.now += DT
        self.sim_drives.apply()
        self.sim.step()
        self.sim_drives.publish()

    def step(self, targets: dict, *, command: bool = True, feed_state: bool = True) -> dict:
        """One control step: command, simulated drives apply, physics, publish, read, check."""
        self.now += DT
        if command:
            self.drives.command(targets, self.now)
        self.sim_drives.apply()
        self.sim.step()
        self.sim_drives.publish()
        state = self.drives.read() if command else None
        if feed_state:
            self.drives.feed_state(self.now)
        self.drives.check(self.now)
        return state

    def joints(self) -> list[float]:
        return self.sim.joint_states()[0]

    def states(self) -> dict[int, str]:
        return {n: d.state for n, d in self.sim_drives.drives.items()}

    def close(self) -> None:
        self.drives.close()
        self.sim_drives.close()
        self.sim.close()


@pytest.fixture
def make_table():
    made = []

    def make(config: TableConfig | None = None, **kwargs) -> Table:
        table = Table(config or keeper_config(), **kwargs)
        made.append(table)
        return table

    yield make
    for table in made:
        table.close()


def test_the_driver_imports_neither_pybullet_nor_the_simulator():
    code = (
        "import sys; from foosball_gym.real_table.hardware import TableDrives, load_config;"
        "import foosball_gym.real_table.hardware.cia402, foosball_gym.real_table.hardware.safety;"
        "bad = {'pybullet', 'foosball_gym.sim'} & set(sys.modules);"
        "assert not bad, bad"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


# ---------------------------------------------------------------------------- configuration


def test_shipped_keeper_table_has_the_papers_bus_and_nodes_and_the_tables_limits():
    config = load_config(shipped_table("keeper"))
    assert (config.bus.interface, config.bus.channel, config.bus.bitrate) == (
        "socketcan",
        "can0",
        1_000_000,
    )
    assert {j.key: j.node_id for j in config.joints} == {SLIDE: 1, SPIN: 2}
    assert config.mode == "csp" and config.control_hz == 60 and config.watchdog_s == 0.05
    slide, spin = config.joint(SLIDE), config.joint(SPIN)
    assert slide.hard_limit == rod("home_keeper").slide_limit and spin.hard_limit == SPIN_LIMIT
    assert slide.max_speed == SLIDE_MAX_SPEED and spin.max_speed == SPIN_MAX_SPEED


def test_config_save_and_load_round_trip(tmp_path):
    config = load_config(shipped_table())
    config.joint(SPIN).offset = -1234  # what a calibration step writes
    config.joint(SLIDE).direction = -1
    config.camera["intrinsics"] = [[1000.0, 0.0, 640.0], [0.0, 1000.0, 360.0], [0.0, 0.0, 1.0]]
    path = tmp_path / "table.yaml"
    save_config(config, path)
    assert load_config(path) == config
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


@pytest.mark.parametrize(
    "change, field, hint",
    [
        (lambda d: d["joints"][0].update(rod="home_goalie"), "joints[0].rod", "home_keeper"),
        (lambda d: d["joints"][1].update(joint="tilt"), "joints[1].joint", "slide, spin"),
        (lambda d: d["joints"][1].update(node_id=1), "joints[1].node_id", "already used"),
        (lambda d: d["joints"][0].update(node_id=200), "joints[0].node_id", "1 to 127"),
        (
            lambda d: d["joints"][0].update(increments_per_unit=0),
            "joints[0].increments_per_unit",
            "positive",
        ),
        (lambda d: d["joints"][0].update(direction=0), "joints[0].direction", "1, -1"),
        (lambda d: d["joints"][0].update(limit_margin=0.2), "joints[0].limit_margin", "0.123"),
        (
            lambda d: d["joints"][0].update(limit_margin=0),
            "joints[0].limit_margin",
            "must lie in (0, 0.123) m",
        ),
        (
            lambda d: d["joints"][0].update(max_acceleration=10_000),
            "joints[0].max_acceleration",
            "must lie in (0, 96.55] m/s^2",
        ),
        (
            lambda d: d["joints"][1].update(max_acceleration=1e6),
            "joints[1].max_acceleration",
            "must lie in (0, 2.889e+04] rad/s^2",
        ),
        (
            lambda d: d["joints"][1].update(max_acceleration=0),
            "joints[1].max_acceleration",
            "must lie in (0, 2.889e+04] rad/s^2",
        ),
        (lambda d: d["joints"][0].update(max_speed=5.0), "joints[0].max_speed", "limit 4"),
        (lambda d: d["joints"][0].update(speed=1.0), "joints[0].speed", "allowed: rod"),
        (lambda d: d["joints"].append(dict(d["joints"][0], node_id=3)), "joints[2]", "already"),
        (lambda d: d.update(mode="velocity"), "mode", "csp, pp"),
        (lambda d: d["bus"].update(bitrate=1_000_001), "bus.bitrate", "1000000"),
        (lambda d: d["bus"].update(interface="carrier-pigeon"), "bus.interface", "socketcan"),
        (lambda d: d.update(watchdog_s=-1), "watchdog_s", "must lie in 0.01667 to 0.1 s"),
        (lambda d: d.update(watchdog_s=0.01), "watchdog_s", "at least one control period"),
        (lambda d: d.update(watchdog_s=10), "watchdog_s", "must lie in 0.01667 to 0.1 s"),
        (lambda d: d.update(heartbeat_timeout_s=60), "heartbeat_timeout_s", "at most 0.5 s"),
        (lambda d: d.update(heartbeat_timeout_s=0), "heartbeat_timeout_s", "above 0 and at"),
        (lambda d: d.update(control_hz=30), "control_hz", "40 to 1000 Hz"),
        (lambda d: d.update(control_hz=5000), "control_hz", "40 to 1000 Hz"),
        (lambda d: d.update(camera=[1, 2]), "camera", "mapping"),
        (lambda d: d.pop("joints"), "joints", "missing"),
    ],
)
def test_config_errors_name_the_field_and_what_is_allowed(tmp_path, change, field, hint):
    import yaml

    data = yaml.safe_load(shipped_table().read_text())
    change(data)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError) as info:
        load_config(path)
    assert info.value.field == field
    assert hint in str(info.value) and str(path) in str(info.value)
    assert "\n" not in str(info.value)


# ---------------------------------------------------------------------------- safety, pure


def test_limiter_keeps_extreme_noisy_targets_inside_limits_speed_and_acceleration():
    limits = JointLimits(-0.118, 0.118, 4.0, 50.0)
    limiter = TargetLimiter(limits, DT, position=0.0)
    rng = np.random.default_rng(0)
    positions, velocities = [0.0], [0.0]
    for _ in range(2000):
        target = float(rng.choice([-1e3, 1e3, 0.0, 0.1]) + rng.normal(0, 0.05))
        positions.append(limiter.step(target))
        velocities.append(limiter.velocity)
    p, v = np.array(positions), np.array(velocities)
    assert p.min() >= limits.lower and p.max() <= limits.upper
    assert np.abs(v).max() <= limits.max_speed + 1e-9
    assert np.abs(np.diff(v)).max() <= limits.max_acceleration * DT + 1e-9
    np.testing.assert_allclose(np.diff(p) / DT, v[1:], atol=1e-9)


def test_limiter_reaches_a_target_and_stays_there():
    limiter = TargetLimiter(JointLimits(-0.118, 0.118, 4.0, 50.0), DT, position=-0.1)
    for _ in range(60):
        limiter.step(0.05)
    assert limiter.position == pytest.approx(0.05, abs=1e-12) and limiter.velocity == 0.0


def test_limiter_brings_a_joint_parked_outside_its_limits_back_at_the_rate_limits():
    limits = JointLimits(-0.1, 0.1, 1.0, 10.0)
    limiter = TargetLimiter(limits, DT, position=0.12)
    positions = [0.12] + [limiter.step(1.0) for _ in range(30)]  # asks to go further out
    velocities = np.diff(positions) / DT
    assert max(positions) == 0.12 and positions[-1] == pytest.approx(0.1)
    assert np.abs(velocities).max() <= limits.max_speed
    assert np.abs(np.diff([0.0, *velocities])).max() <= limits.max_acceleration * DT + 1e-9


def test_watchdog_trips_on_a_stale_command_or_state_estimate():
    dog = Watchdog(0.05)
    dog.check(100.0)  # not armed before the first command
    dog.feed_command(0.0)
    dog.check(0.04)
    dog.feed_command(0.03)
    with pytest.raises(WatchdogTripped, match="state estimate") as info:
        dog.check(0.06)  # no estimate since the first command
    assert info.value.age == pytest.approx(0.06)
    dog.feed_state(0.06)
    dog.check(0.07)
    with pytest.raises(WatchdogTripped, match="command"):
        dog.check(0.09)  # the last command was at 0.03
    dog.feed_command(0.09)
    dog.check(0.1)


# ---------------------------------------------------------------------------- drives on the bus


@pytest.mark.parametrize("mode", ["csp", "pp"])
def test_bring_up_reaches_operation_enabled_from_a_fresh_node(make_table, mode):
    table = make_table(keeper_config(mode))
    assert table.states() == {1: "SWITCH ON DISABLED", 2: "SWITCH ON DISABLED"}
    positions = table.drives.bring_up()
    assert positions == {SLIDE: 0.0, SPIN: 0.0}
    for drive in table.sim_drives.drives.values():
        assert drive.state == OPERATION_ENABLED
        assert state_name(drive.statusword) == OPERATION_ENABLED
        assert drive.mode_display == {"csp": 8, "pp": 1}[mode]
        assert drive.node.nmt.state == "OPERATIONAL"


@pytest.mark.parametrize("mode", ["csp", "pp"])
def test_bring_up_resets_a_faulted_node(make_table, mode):
    table = make_table(keeper_config(mode))
    table.sim_drives.inject_fault(2, 0x2310)
    assert table.states()[2] == "FAULT"
    table.drives.bring_up()
    assert table.states() == {1: OPERATION_ENABLED, 2: OPERATION_ENABLED}
    assert table.sim_drives.drive(2).error_register == 0
    table.step({SLIDE: 0.01})  # the EMCY from before the reset is no fault now
    table.sim_drives.inject_fault(1, 0x7300)  # a fault while playing: stopped ...
    with pytest.raises(DriveFault):
        table.step({SLIDE: 0.02})
    table.drives.bring_up()  # ... and started again
    assert table.states() == {1: OPERATION_ENABLED, 2: OPERATION_ENABLED}
    for _ in range(3):
        table.step({SLIDE: 0.02, SPIN: 0.3})


@pytest.mark.parametrize("mode", ["csp", "pp"])
def test_targets_reach_the_drives_in_increments_with_scale_offset_and_sign(make_table, mode):
    table = make_table(keeper_config(mode, slide={"offset": 500}, spin={"offset": -2000}))
    table.drives.bring_up()
    wanted = {SLIDE: 0.05, SPIN: -1.5}
    for _ in range(120):
        table.step(wanted)
        if table.sim_drives.drive(1).target == 5500 and table.sim_drives.drive(2).target == -500:
            break
    # slide: 500 + (+1) * 100000 * 0.05; spin: -2000 + (-1) * 1000 * (-1.5)
    assert table.sim_drives.drive(1).target == 5500
    assert table.sim_drives.drive(2).target == -500
    for _ in range(30):
        state = table.step(wanted)
    slide, spin = table.joints()
    assert slide == pytest.approx(0.05, abs=1e-4) and spin == pytest.approx(-1.5, abs=2e-3)
    assert state[SLIDE][0] == pytest.approx(slide, abs=1e-5)
    assert state[SPIN][0] == pytest.approx(spin, abs=1e-3)


def test_limits_and_speeds_hold_against_a_policy_of_extremes_and_noise(make_table):
    table = make_table(
        keeper_config(
            slide={"max_speed": 1.0, "max_acceleration": 30.0},
            spin={"max_speed": 30.0, "max_acceleration": 1000.0},
        )
    )
    table.drives.bring_up()
    slide_cfg, spin_cfg = table.config.joint(SLIDE), table.config.joint(SPIN)
    rng = np.random.default_rng(1)
    joints, targets = [], []
    for _ in range(240):
        table.step(
            {
                SLIDE: float(rng.choice([-10.0, 10.0, 0.0]) + rng.normal(0, 0.05)),
                SPIN: float(rng.choice([-100.0, 100.0]) + rng.normal(0, 1.0)),
            }
        )
        pos, vel = table.sim.joint_states()
        joints.append((*pos, *vel))
        targets.append(
            (
                slide_cfg.from_increments(table.sim_drives.drive(1).target),
                spin_cfg.from_increments(table.sim_drives.drive(2).target),
            )
        )
    joints, targets = np.array(joints), np.array(targets)
    reach = np.array([rod("home_keeper").slide_limit - 0.005, SPIN_LIMIT - 0.1])
    speed = np.array([1.0, 30.0])
    increment = np.array([1e-5, 1e-3])
    assert (np.abs(targets) <= reach + increment).all()
    assert (np.abs(joints[:, :2]) <= reach + increment).all()
    assert (np.abs(np.diff(targets, axis=0)) <= speed * DT + increment).all()
    assert (np.abs(joints[:, 2:]) <= speed).all()
    # The policy pushed both joints to their ends: the limits were reached, not avoided.
    assert (np.abs(joints[:, :2]).max(axis=0) > reach - 0.01).all()


@pytest.mark.parametrize("stale", ["state estimate", "command"])
def test_watchdog_quick_stops_the_drives_which_brake_on_their_ramp_then_switch_off(
    make_table, stale
):
    table = make_table()
    table.drives.bring_up()
    for _ in range(20):
        table.step({SLIDE: 0.1, SPIN: 3.0})
    with pytest.raises(WatchdogTripped) as info:
        for _ in range(5):
            if stale == "state estimate":
                table.step({SLIDE: -0.1, SPIN: -3.0}, feed_state=False)
            else:
                table.step({}, command=False)
    assert info.value.what == stale
    for drive in table.sim_drives.drives.values():
        assert drive.controlword == CW_QUICK_STOP
        # Braking, or already halted and switched off (a joint that stood still)
        assert state_name(drive.statusword) in ("QUICK STOP ACTIVE", "SWITCH ON DISABLED")
    stopped_at, speed_at_stop = (np.array(v) for v in table.sim.joint_states())
    trace = []
    for _ in range(60):
        table.advance()
        trace.append(table.joints())
    positions, velocities = table.sim.joint_states()
    # Braked on the quick stop ramp (max_acceleration), in the direction it was going, then
    # stood still: no further than the ramp's stopping distance plus the joint's lag behind it.
    deceleration = np.array([j.max_acceleration for j in table.config.joints])
    travel = np.array(positions) - stopped_at
    braking = speed_at_stop**2 / (2 * deceleration)
    assert (np.abs(travel) <= braking + np.abs(speed_at_stop) / np.array([48.0, 72.0])).all()
    assert (travel * speed_at_stop >= 0).all()
    np.testing.assert_allclose(trace[-20:], [positions] * 20, atol=1e-4)
    np.testing.assert_allclose(velocities, 0.0, atol=1e-3)
    for drive in table.sim_drives.drives.values():
        # Halted, then the power went off by the drive's own doing (0x605A = 2), at standstill.
        after = [e for e in drive.events if e.what in ("halted", "power off")]
        assert [e.what for e in after] == ["halted", "power off"]
        assert [e.speed for e in after] == [0.0, 0.0]
        assert state_name(drive.statusword) == "SWITCH ON DISABLED"
    with pytest.raises(WatchdogTripped):  # stays stopped until brought up again
        table.drives.command({SLIDE: 0.0}, table.now + DT)


@pytest.mark.parametrize("mode", ["csp", "pp"])
@pytest.mark.parametrize("source", ["EMCY", "statusword", "heartbeat"])
def test_a_drive_fault_stops_every_drive_and_names_the_node_and_why(make_table, mode, source):
    table = make_table(keeper_config(mode))
    table.drives.bring_up()
    for _ in range(5):
        table.step({SLIDE: 0.02, SPIN: 0.5})
    faulty, healthy = (2, 1) if source != "heartbeat" else (1, 2)
    if source == "EMCY":
        table.sim_drives.inject_fault(faulty, 0x2310)
        expected = "EMCY Code 0x2310"
    elif source == "statusword":
        table.sim_drives.inject_fault(faulty, emcy=False)
        expected = "fault bit"
    else:
        table.sim_drives.stop_heartbeat(faulty)
        expected = "heartbeat lost"
    deadline = time.monotonic() + 2.0
    with pytest.raises(DriveFault) as info:
        while time.monotonic() < deadline:
            table.step({SLIDE: 0.02, SPIN: 0.5})
    assert info.value.node_id == faulty
    assert expected in info.value.reason
    assert f"node {faulty}" in str(info.value)
    assert table.sim_drives.drive(healthy).state == "QUICK STOP ACTIVE"
    assert OPERATION_ENABLED not in table.states().values()
    with pytest.raises(DriveFault):
        table.drives.command({SLIDE: 0.0}, table.now + DT)


@pytest.mark.parametrize("bad", [{SLIDE: math.nan}, {("home_keeper", "tilt"): 0.0}])
def test_a_nonsense_command_stops_every_drive(make_table, bad):
    table = make_table()
    table.drives.bring_up()
    table.step({SLIDE: 0.02})
    with pytest.raises(UnsafeCommand):
        table.step(bad)
    assert table.states() == {1: "QUICK STOP ACTIVE", 2: "QUICK STOP ACTIVE"}


@pytest.mark.parametrize("error", [KeyboardInterrupt, RuntimeError])
def test_leaving_the_with_block_by_ctrl_c_or_an_exception_disables_the_drives(error):
    config = keeper_config()
    sim = TableSim(["home_keeper"])
    try:
        with SimulatedDrives(config, sim) as sim_drives:
            with pytest.raises(error):
                with TableDrives(config) as drives:
                    drives.bring_up()
                    for k in range(5):
                        drives.command({SLIDE: 0.05}, k * DT)
                        sim_drives.apply()
                        sim.step()
                        sim_drives.publish()
                        drives.read()
                        drives.feed_state(k * DT)
                    assert {d.state for d in sim_drives.drives.values()} == {OPERATION_ENABLED}
                    raise error("stop")
            sim_drives.apply()  # let the nodes process the last frames (NMT)
            for drive in sim_drives.drives.values():
                # Braked by a quick stop first; disable voltage is the way out of it.
                assert drive.state == "SWITCH ON DISABLED"
                assert drive.node.nmt.state == "PRE-OPERATIONAL"
    finally:
        sim.close()
