"""The configuration of a real table: its CAN bus, its drives and their calibration.

A table configuration is a YAML file (see ``tables/keeper.yaml``) that :func:`load_config`
reads into a :class:`TableConfig` and :func:`save_config` writes back, so a calibration step
can store what it measured. Everything is checked on load, and an error names the field and
what it allows.

Joint values are in the simulator's convention (metres for ``slide``, radians for ``spin``, the
away rods mirrored), so a policy's targets mean the same thing on either table. Each joint maps
them to drive increments as ``increments = offset + direction * increments_per_unit * value``.
The joint limits and the drives' top speeds come from :mod:`foosball_gym.table`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from foosball_gym import table
from foosball_gym.policy_io.target_limits import DEFAULT_LIMIT_MARGIN

Joint = tuple[str, str]  # (rod name, "slide" | "spin"), as in foosball_gym.policy_io.task

JOINT_KINDS = ("slide", "spin")
DRIVE_MODES = ("csp", "pp")
# The drives' interpolation time period (0x60C2) is a count of 0.1 ms in 8 bits: below 40 Hz it
# overflows, and above 1 kHz the count is so small that rounding it misstates the period by
# several per cent.
CONTROL_HZ_RANGE = (40.0, 1000.0)
# Beyond these a stalled loop or a dead drive would go unnoticed while the rods keep moving.
MAX_WATCHDOG_S = 0.1
MAX_HEARTBEAT_TIMEOUT_S = 0.5
# The bit rates CiA 301 defines for CANopen.
BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
UINT32_MAX = 2**32 - 1

# Defaults for a joint that does not set them (its margin: DEFAULT_LIMIT_MARGIN): accelerations
# well inside what the drives reach (70 N on about 0.8 kg of rod and carriage;
# 1.41 N m on a rod of a few 1e-5 kg m^2), to be replaced by measured values.
DEFAULT_MAX_ACCELERATION = {"slide": 50.0, "spin": 3000.0}


class ConfigError(ValueError):
    """A table configuration that cannot be used.

    Attributes:
        field: the offending field, as a path (``"joints[1].node_id"``).
        problem: what is wrong and what is allowed.
    """

    def __init__(self, field: str, problem: str, source: str | None = None) -> None:
        self.field = field
        self.problem = problem
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{field}: {problem}")

    def within(self, prefix: str) -> ConfigError:
        """The same error for a field nested under ``prefix``."""
        return ConfigError(f"{prefix}.{self.field}", self.problem, self.source)


def _number(name: str, value: Any, *, positive: bool = False) -> float:
    # bool is an int to Python, but "true" for a scale is a mistake in the file.
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(name, f"must be a finite number, got {value!r}")
    if positive and value <= 0:
        raise ConfigError(name, f"must be positive, got {value!r}")
    return float(value)


def _integer(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ConfigError(name, f"must be an integer, got {value!r}")
    return value


def _choice(name: str, value: Any, allowed: tuple) -> Any:
    if value not in allowed:
        raise ConfigError(
            name, f"unknown value {value!r}; allowed: {', '.join(str(a) for a in allowed)}"
        )
    return value


@dataclass
class BusConfig:
    """The CAN bus, as python-can opens it.

    Attributes:
        interface: a python-can interface name (``socketcan``, ``pcan``, ``virtual``, ...).
        channel: the interface's channel (``can0``, ``PCAN_USBBUS1``, a virtual bus name, ...).
        bitrate: bits per second, one of the CANopen rates (1 Mbit/s on the paper's table).
    """

    interface: str = "socketcan"
    channel: str | int = "can0"
    bitrate: int = 1_000_000

    def __post_init__(self) -> None:
        if not isinstance(self.interface, str) or not self.interface:
            raise ConfigError("interface", f"must be a name, got {self.interface!r}")
        try:
            from can.interfaces import VALID_INTERFACES
        except ImportError:
            pass  # a configuration is also read where no bus is driven (vision, estimation)
        else:
            _choice("interface", self.interface, tuple(sorted(VALID_INTERFACES)))
        if isinstance(self.channel, bool) or not isinstance(self.channel, (str, int)):
            raise ConfigError("channel", f"must be a name or a number, got {self.channel!r}")
        if isinstance(self.channel, str) and not self.channel:
            raise ConfigError("channel", "must not be empty")
        _choice("bitrate", _integer("bitrate", self.bitrate), BITRATES)


@dataclass
class JointConfig:
    """One joint of one rod and the drive that moves it.

    Attributes:
        rod: the rod's name in :data:`foosball_gym.table.RODS` (``"home_keeper"``, ...).
        joint: ``"slide"`` (prismatic) or ``"spin"`` (revolute).
        node_id: the drive's CANopen node id, 1 to 127.
        increments_per_unit: drive increments per metre (slide) or per radian (spin); the
            drive's velocity and acceleration units are taken to be increments per second and
            per second squared.
        direction: +1 or -1: the sign between the joint's value and the drive's increments.
        offset: the drive's position, in increments, at joint value 0.
        limit_margin: how far the targets stay inside the table's joint limit (m or rad), more
            than 0.
        max_speed: the fastest the targets may move (m/s or rad/s); at most, and by default,
            the table's drive limit.
        max_acceleration: the fastest the targets' speed may change (m/s^2 or rad/s^2), and the
            drives' stop ramps; at most what the drive can reach
            (:func:`foosball_gym.table.drive_acceleration`).
    """

    rod: str
    joint: str
    node_id: int
    increments_per_unit: float
    direction: int = 1
    offset: int = 0
    limit_margin: float | None = None
    max_speed: float | None = None
    max_acceleration: float | None = None

    def __post_init__(self) -> None:
        _choice("rod", self.rod, tuple(table.ROD_BY_NAME))
        _choice("joint", self.joint, JOINT_KINDS)
        node_id = _integer("node_id", self.node_id)
        if not 1 <= node_id <= 127:
            raise ConfigError("node_id", f"must be a CANopen node id, 1 to 127, got {node_id}")
        self.increments_per_unit = _number(
            "increments_per_unit", self.increments_per_unit, positive=True
        )
        _choice("direction", _integer("direction", self.direction), (1, -1))
        _integer("offset", self.offset)
        if self.limit_margin is None:
            self.limit_margin = DEFAULT_LIMIT_MARGIN[self.joint]
        unit = "m" if self.joint == "slide" else "rad"
        self.limit_margin = _number("limit_margin", self.limit_margin)
        # A margin of 0 lets the targets reach the end stop itself.
        if not 0 < self.limit_margin < self.hard_limit:
            raise ConfigError(
                "limit_margin",
                f"must lie in (0, {self.hard_limit:g}) {unit}: above 0, so that no target reaches "
                f"the end stop, and below the {self.joint} limit of {self.rod}; "
                f"got {self.limit_margin:g}",
            )
        top = self.drive_max_speed
        if self.max_speed is None:
            self.max_speed = top
        self.max_speed = _number("max_speed", self.max_speed, positive=True)
        if self.max_speed > top:
            raise ConfigError(
                "max_speed", f"must not exceed the table's {self.joint} drive limit {top:g}"
            )
        if self.max_acceleration is None:
            self.max_acceleration = DEFAULT_MAX_ACCELERATION[self.joint]
        self.max_acceleration = _number("max_acceleration", self.max_acceleration)
        # Beyond what the drive can do, the rate limit and the stop ramps (0x6084, 0x6085) ask
        # for a braking the drive cannot give: in effect no limit and no ramp.
        reach = table.drive_acceleration(table.rod(self.rod), self.joint)
        if not 0 < self.max_acceleration <= reach:
            raise ConfigError(
                "max_acceleration",
                f"must lie in (0, {reach:.4g}] {unit}/s^2, at most what the {self.rod} "
                f"{self.joint} drive can reach; got {self.max_acceleration:g}",
            )
        # Every position in the joint's range must fit the drive's int32 objects, and the
        # profile speeds its uint32 ones.
        for end in (-self.hard_limit, self.hard_limit):
            if not INT32_MIN <= self.to_increments(end) <= INT32_MAX:
                raise ConfigError(
                    "increments_per_unit",
                    f"maps the joint limit {end:g} outside the drive's int32 range",
                )
        if self.max_acceleration * self.increments_per_unit > UINT32_MAX:
            raise ConfigError(
                "max_acceleration", "in increments/s^2 exceeds the drive's uint32 range"
            )

    @property
    def key(self) -> Joint:
        return (self.rod, self.joint)

    @property
    def hard_limit(self) -> float:
        """The table's joint limit: the joint moves in ``[-hard_limit, hard_limit]``."""
        return table.rod(self.rod).slide_limit if self.joint == "slide" else table.SPIN_LIMIT

    @property
    def drive_max_speed(self) -> float:
        return table.SLIDE_MAX_SPEED if self.joint == "slide" else table.SPIN_MAX_SPEED

    @property
    def label(self) -> str:
        """How errors name this joint: ``"node 2 (home_keeper spin)"``."""
        return f"node {self.node_id} ({self.rod} {self.joint})"

    def to_increments(self, value: float) -> int:
        """A joint value (m or rad) as a drive position in increments."""
        return round(self.offset + self.direction * self.increments_per_unit * value)

    def from_increments(self, increments: float) -> float:
        """A drive position in increments as a joint value (m or rad)."""
        return (increments - self.offset) / (self.direction * self.increments_per_unit)

    def speed_to_increments(self, speed: float) -> int:
        """A speed or acceleration (per s, per s^2) in increments, with the joint's sign."""
        return round(self.direction * self.increments_per_unit * speed)

    def speed_from_increments(self, increments: int) -> float:
        return increments / (self.direction * self.increments_per_unit)


def simulated_joint(
    rod: str, kind: str, node_id: int = 1, increments_per_unit: float = 1.0, direction: int = 1
) -> JointConfig:
    """The configuration of one joint of the simulated table: the safety layer's default
    margin and top speed, and the acceleration the simulated drive reaches (the safety
    layer's default is a guess kept well inside a real drive's, which would make the simulated
    table's rods slower than the environment's)."""
    return JointConfig(
        rod=rod,
        joint=kind,
        node_id=node_id,
        increments_per_unit=increments_per_unit,
        direction=direction,
        max_acceleration=table.drive_acceleration(table.rod(rod), kind),
    )


@dataclass
class TableConfig:
    """A real table: its bus, its drives, and sections other parts of the system fill.

    Attributes:
        joints: the joints with a drive, each once.
        bus: the CAN bus.
        control_hz: control steps per second (the SYNC rate in ``csp``), 40 to 1000.
        mode: ``"csp"``, cyclic synchronous position: every step the targets go out in
            PDOs and one SYNC makes all drives take them and sample their positions at the same
            instant, a few frames per step (the default: it keeps both joints of a rod in step,
            gives every state the same latency and keeps each step well under a millisecond
            of bus time). ``"pp"``, profile position over SDO: each drive runs its own profile
            to the target within ``max_speed`` and ``max_acceleration``, which needs no PDO
            set-up but costs a dozen confirmed SDO transfers per step.
        watchdog_s: the drives stop when the last command, or the last camera frame that
            brought news to the state estimate, is older than this; one control period to
            :data:`MAX_WATCHDOG_S`.
        heartbeat_timeout_s: a drive whose heartbeat is older than this counts as lost, and a
            drive that hears nothing of the master for this long stops by itself; the drives
            are told to beat three times as often. At most :data:`MAX_HEARTBEAT_TIMEOUT_S`.
        camera, vision, estimation: free-form sections for the camera, the detector and the
            Kalman filter.
    """

    joints: list[JointConfig]
    bus: BusConfig = field(default_factory=BusConfig)
    control_hz: float = float(table.CONTROL_HZ)
    mode: str = "csp"
    watchdog_s: float = 0.05
    heartbeat_timeout_s: float = 0.1
    camera: dict[str, Any] = field(default_factory=dict)
    vision: dict[str, Any] = field(default_factory=dict)
    estimation: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.joints, list) or not self.joints:
            raise ConfigError("joints", "must be a non-empty list of joints")
        node_ids: dict[int, int] = {}
        keys: dict[Joint, int] = {}
        for i, joint in enumerate(self.joints):
            if not isinstance(joint, JointConfig):
                raise ConfigError(f"joints[{i}]", f"must be a JointConfig, got {joint!r}")
            if joint.node_id in node_ids:
                raise ConfigError(
                    f"joints[{i}].node_id",
                    f"node id {joint.node_id} is already used by joints[{node_ids[joint.node_id]}]",
                )
            if joint.key in keys:
                raise ConfigError(
                    f"joints[{i}]",
                    f"{joint.rod} {joint.joint} is already configured in joints[{keys[joint.key]}]",
                )
            node_ids[joint.node_id] = i
            keys[joint.key] = i
        self.control_hz = _number("control_hz", self.control_hz)
        low, high = CONTROL_HZ_RANGE
        if not low <= self.control_hz <= high:
            raise ConfigError(
                "control_hz",
                f"must lie in {low:g} to {high:g} Hz (the drives take the SYNC period as a "
                f"count of 0.1 ms up to 255), got {self.control_hz:g}",
            )
        _choice("mode", self.mode, DRIVE_MODES)
        self.watchdog_s = _number("watchdog_s", self.watchdog_s)
        period = self.control_period
        if not period <= self.watchdog_s <= MAX_WATCHDOG_S:
            raise ConfigError(
                "watchdog_s",
                f"must lie in {period:.4g} to {MAX_WATCHDOG_S:g} s: at least one control period "
                f"at {self.control_hz:g} Hz, which a loop on time takes between two commands, "
                f"and at most {MAX_WATCHDOG_S:g} s, so that a stalled loop stops the rods "
                f"within it; got {self.watchdog_s:g}",
            )
        self.heartbeat_timeout_s = _number("heartbeat_timeout_s", self.heartbeat_timeout_s)
        if not 0 < self.heartbeat_timeout_s <= MAX_HEARTBEAT_TIMEOUT_S:
            raise ConfigError(
                "heartbeat_timeout_s",
                f"must be above 0 and at most {MAX_HEARTBEAT_TIMEOUT_S:g} s, so that a lost "
                f"drive, or a lost master, is noticed within it; got {self.heartbeat_timeout_s:g}",
            )
        for name in ("camera", "vision", "estimation"):
            if not isinstance(getattr(self, name), dict):
                raise ConfigError(name, f"must be a mapping, got {getattr(self, name)!r}")

    @property
    def control_period(self) -> float:
        return 1.0 / self.control_hz

    def joint(self, key: Joint) -> JointConfig:
        for joint in self.joints:
            if joint.key == key:
                return joint
        raise KeyError(f"no drive for {key[0]} {key[1]}; configured: {self.joint_keys()}")

    def joint_keys(self) -> list[Joint]:
        return [j.key for j in self.joints]

    @classmethod
    def from_dict(cls, data: Any) -> TableConfig:
        """Build a configuration from the parsed YAML, checking every field."""
        if not isinstance(data, Mapping):
            raise ConfigError("<top level>", f"must be a mapping, got {type(data).__name__}")
        fields = _fields(cls, data)
        raw_joints = fields["joints"]
        if not isinstance(raw_joints, list):
            raise ConfigError("joints", f"must be a list, got {type(raw_joints).__name__}")
        joints = []
        for i, item in enumerate(raw_joints):
            where = f"joints[{i}]"
            if not isinstance(item, Mapping):
                raise ConfigError(where, f"must be a mapping, got {item!r}")
            try:
                joints.append(JointConfig(**_fields(JointConfig, item)))
            except ConfigError as e:
                raise e.within(where) from None
        fields["joints"] = joints
        if "bus" in fields:
            bus = fields["bus"]
            if not isinstance(bus, Mapping):
                raise ConfigError("bus", f"must be a mapping, got {bus!r}")
            try:
                fields["bus"] = BusConfig(**_fields(BusConfig, bus))
            except ConfigError as e:
                raise e.within("bus") from None
        for name in ("camera", "vision", "estimation"):
            if name in fields and fields[name] is None:  # an empty section in the file
                fields[name] = {}
        return cls(**fields)

    def to_dict(self) -> dict[str, Any]:
        """The configuration as plain data, every default spelled out."""
        return dataclasses.asdict(self)


def _fields(cls: type, data: Mapping) -> dict[str, Any]:
    """``data`` as keyword arguments of ``cls``, refusing unknown keys and missing required ones."""
    names = [f.name for f in dataclasses.fields(cls)]
    for key in data:
        if key not in names:
            raise ConfigError(str(key), f"unknown field; allowed: {', '.join(names)}")
    required = [
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    for name in required:
        if name not in data:
            raise ConfigError(name, "is missing")
    return dict(data)


def _yaml():
    try:
        import yaml
    except ImportError:
        raise ImportError(
            "table configurations need PyYAML: pip install -e '.[hardware]'"
        ) from None
    return yaml


def load_config(path: str | os.PathLike) -> TableConfig:
    """Read and check a table configuration file.

    Raises:
        ConfigError: naming the file, the field and what it allows.
    """
    yaml = _yaml()
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as e:
        # PyYAML's own message quotes the line over several; one line says where.
        problem = getattr(e, "problem", None) or " ".join(str(e).split())
        mark = getattr(e, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        raise ConfigError("<file>", f"is not valid YAML: {problem}{where}", str(path)) from None
    try:
        config = TableConfig.from_dict(data)
    except ConfigError as e:
        raise ConfigError(e.field, e.problem, str(path)) from None
    return config


def save_config(config: TableConfig, path: str | os.PathLike) -> None:
    """Write ``config`` to ``path`` (atomically: a reader never sees half a file).

    Comments of a file that was loaded are not kept.
    """
    yaml = _yaml()
    path = Path(path)
    text = "# foosball_gym table configuration\n" + yaml.safe_dump(
        config.to_dict(), sort_keys=False, default_flow_style=False
    )
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def shipped_table(name: str = "keeper") -> Path:
    """The path of a table configuration shipped with the package (``tables/<name>.yaml``)."""
    folder = Path(str(resources.files("foosball_gym.real_table.hardware") / "tables"))
    path = folder / f"{name}.yaml"
    if not path.is_file():
        shipped = sorted(p.stem for p in folder.glob("*.yaml"))
        raise ValueError(f"no shipped table {name!r}; shipped: {', '.join(shipped)}")
    return path
