"""The simulated table: the only module that imports pybullet.

A :class:`TableSim` owns one ``BulletClient`` (so many tables live in one process), loads the
table URDF with the rods that are in play and the ball, and advances the world in control
steps. Goals and a ball leaving the table are checked after every physics step, so a fast ball
cannot cross the goal line and bounce back out unseen.

How contacts stay right at every speed (measured; see ``benchmarks/physics_report.py``):

- Bullet's continuous collision detection would stop tunnelling, but its predictive contacts
  carry no restitution, so a fast ball died against a wall. The ball has none here. Instead,
  before each control step the simulator bounds where the ball (by its speed) and each
  figurine (by what its drive asks for) can get to. Where the ball could touch a figurine, a
  wall or the surface from above within the step, the step is split into physics steps fine
  enough that nothing moves more than ``contact_travel`` relative to what it may touch (twice
  that near a wall alone, which is flat); while a figurine may meet a fast ball this is
  decided again every base step. Far from everything the table runs at ``physics_hz``.
- Bullet pushes penetrating bodies apart with a velocity (ERP) that adds to a bounce; with
  multibody contacts it cannot be split off, so its gain is kept near zero.
- A position gain in Bullet acts per physics step; the drives' gains here are per second and
  rescaled to whatever step is taken, so a drive behaves the same at every step size.

Rods that are not in play are left out of the loaded model: they cannot touch the ball and cost
nothing to simulate.
"""

from __future__ import annotations

import collections
import contextlib
import ctypes
import functools
import hashlib
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from importlib import resources
from pathlib import Path

import numpy as np

from foosball_gym import table as T
from foosball_gym.camera import CameraModel
from foosball_gym.physics_options import check_physics


def _libc_fflush() -> None:
    # C's stdio buffers what Bullet prints; flush it while stdout still points at /dev/null.
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).fflush(None)


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silence what Bullet's C++ code prints (build time, URDF merge notes) on fds 1 and 2.

    Failures still surface: pybullet raises an exception for anything that goes wrong.
    """
    with contextlib.suppress(Exception):
        sys.stdout.flush()
        sys.stderr.flush()
    saved = [os.dup(fd) for fd in (1, 2)]
    try:
        with open(os.devnull, "w") as devnull:
            for fd in (1, 2):
                os.dup2(devnull.fileno(), fd)
        yield
    finally:
        _libc_fflush()
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)


with _quiet_stdout():
    import pybullet
    from pybullet_utils.bullet_client import BulletClient

NO_GOAL, HOME_SCORED, AWAY_SCORED = T.NO_GOAL, T.HOME_SCORED, T.AWAY_SCORED

# The names :meth:`TableSim.keyboard_events` gives PyBullet's codes of keys without a character.
_KEY_NAMES = {
    pybullet.B3G_LEFT_ARROW: "left",
    pybullet.B3G_RIGHT_ARROW: "right",
    pybullet.B3G_UP_ARROW: "up",
    pybullet.B3G_DOWN_ARROW: "down",
    pybullet.B3G_SPACE: "space",
    pybullet.B3G_RETURN: "return",
}
# Where :meth:`TableSim.show_text` writes: beyond the side walls, a line apart (m).
_TEXT_MARGIN = 0.09
_TEXT_LINE = 0.04

CONTROL_MODES = ("position", "velocity", "torque")


def urdf_path(name: str = "foosball_table.urdf") -> Path:
    """Path of a URDF shipped with the package (``urdf/`` of the source tree)."""
    try:
        return Path(str(resources.files("foosball_gym.urdf") / name))
    except ModuleNotFoundError:
        # A source checkout imported straight from its directory has no mapped subpackage.
        return Path(__file__).resolve().parents[1] / "urdf" / name


@cache
def _urdf_with_rods(rod_names: tuple[str, ...]) -> str:
    """The table URDF with only the given rods, written once per process and rod set."""
    tree = ET.parse(urdf_path())
    robot = tree.getroot()
    keep = set(rod_names)

    def rod_of(name: str) -> str | None:
        for rod in T.RODS:
            if name.startswith(rod.name + "_"):
                return rod.name
        return None

    for el in list(robot):
        if el.tag in ("link", "joint"):
            owner = rod_of(el.get("name", ""))
            if owner is not None and owner not in keep:
                robot.remove(el)
    _merge_fixed_links(robot)
    # The copy lives elsewhere, so the meshes it names are given by their full path.
    for mesh in robot.iter("mesh"):
        mesh.set("filename", str(urdf_path(mesh.get("filename", ""))))
    text = ET.tostring(robot, encoding="unicode")
    # Named by content, so processes share one file and a changed table gets a new one.
    digest = hashlib.sha1(text.encode()).hexdigest()[:16]
    path = Path(tempfile.gettempdir()) / f"foosball_gym_{digest}.urdf"
    # Anyone can write to the temp folder: a file under this name is used only if it holds
    # exactly this table.
    if not _holds(path, text):
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".urdf")
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    return str(path)


def _holds(path: Path, text: str) -> bool:
    try:
        return path.read_text() == text
    except (OSError, UnicodeDecodeError):
        return False


def _merge_fixed_links(robot: ET.Element) -> None:
    """Fold every link on a fixed joint (the figurines) into its parent (the rod).

    This is what Bullet's ``URDF_MERGE_FIXED_LINKS`` does, done before loading because that
    flag leaks about 100 kB of Bullet's memory per load. The order Bullet merges in (a
    parent's first child, then the others last to first) and the way it sums the centre of
    mass are kept, so the table is the same to the last bit.
    """
    links = {link.get("name"): link for link in robot.findall("link")}
    children: dict[str, list[ET.Element]] = {}
    for joint in robot.findall("joint"):
        if joint.get("type") == "fixed":
            children.setdefault(joint.find("parent").get("link"), []).append(joint)
    for parent_name, joints in children.items():
        parent = links[parent_name]
        inertial = parent.find("inertial")
        mass = float(inertial.find("mass").get("value"))
        com = [float(v) for v in inertial.find("origin").get("xyz").split()]
        for joint in joints[:1] + joints[:0:-1]:
            child = links[joint.find("child").get("link")]
            offset = [float(v) for v in joint.find("origin").get("xyz").split()]
            if any(float(v) for v in joint.find("origin").get("rpy", "0 0 0").split()):
                raise ValueError(f"fixed joint {joint.get('name')} is turned; not merged")
            child_inertial = child.find("inertial")
            child_mass = float(child_inertial.find("mass").get("value"))
            child_com = [
                float(v) + o
                for v, o in zip(child_inertial.find("origin").get("xyz").split(), offset)
            ]
            total = mass + child_mass
            com = [(mass * a + child_mass * b) * (1 / total) for a, b in zip(com, child_com)]
            mass = total
            for element in child:
                if element.tag in ("visual", "collision"):
                    origin = element.find("origin")
                    xyz = [float(v) for v in origin.get("xyz").split()]
                    origin.set("xyz", " ".join(repr(v + o) for v, o in zip(xyz, offset)))
                    parent.append(element)
            robot.remove(child)
            robot.remove(joint)
        inertial.find("mass").set("value", repr(mass))
        inertial.find("origin").set("xyz", " ".join(repr(v) for v in com))


@dataclass
class BallState:
    position: np.ndarray  # (3,) metres
    velocity: np.ndarray  # (3,) m/s


def _rod_spin_inertia(rod: T.Rod) -> float:
    """The rod's moment of inertia about its axis, figurines included (kg m^2), as the URDF
    gives it."""
    fx, _, fz = T.FIGURINE_SIZE
    figurine = T.FIGURINE_MASS * (T.FIGURINE_CENTRE_BELOW_AXIS**2 + (fx * fx + fz * fz) / 12)
    return T.ROD_MASS * T.ROD_RADIUS**2 / 2 + len(rod.figurine_offsets) * figurine


def drive_acceleration(rod: T.Rod, joint: str) -> float:
    """The most a drive can change its joint's speed per second, with nothing else pushing
    (m/s^2 for ``"slide"``, rad/s^2 for ``"spin"``)."""
    if joint == "slide":
        moving = T.CARRIAGE_MASS + T.ROD_MASS + len(rod.figurine_offsets) * T.FIGURINE_MASS
        return T.SLIDE_MAX_FORCE / moving
    if joint == "spin":
        return T.SPIN_MAX_TORQUE / _rod_spin_inertia(rod)
    raise ValueError(f"joint must be 'slide' or 'spin', got {joint!r}")


# Where a figurine can be, in the plane across its rod (distances from the rod's axis): the
# body, a box round the axis, reaches _BODY_REACH; the leg spans _LEG_INNER.._LEG_OUTER (the
# reach of the sole) within _LEG_HALF_ANGLE either side of the line the spin angle points along.
_BODY_REACH = math.hypot(T.ROD_HEIGHT - T.FIGURINE_LEG_TOP, T.FIGURINE_SIZE[0] / 2)
_LEG_INNER = T.ROD_HEIGHT - T.FIGURINE_LEG_TOP
_LEG_OUTER = T.FIGURINE_REACH
_LEG_HALF_ANGLE = math.atan2(max(max(-x0, x1) for _, x0, x1 in T.FIGURINE_LEG_SECTIONS), _LEG_INNER)
_FIGURINE_HALF_WIDTH = T.FIGURINE_SIZE[1] / 2
# What a check of "could these touch within the step" adds to the distances, for the rounding
# of everything it leaves out (the ball's spin, contact slop).
_NEAR_MARGIN = 0.002
# How fast (1/s) Bullet pushes penetrating bodies apart. The velocity it adds also adds to a
# bounce, and for contacts with a multibody (the table, a figurine) it cannot be split off:
# Bullet's 0.2 per step made a wall rebound keep 0.51-0.70 of the normal speed instead of 0.5;
# 0.01 per 240 Hz step keeps 0.48-0.51, and a ball at rest still sits on the surface to 0.01 mm.
# Per second, so that finer steps do not push harder.
_ERP_RATE = 0.01 * T.PHYSICS_HZ
# Near a wall alone, physics steps may be this many times the contact travel (see
# _steps_needed): rebounds keep 0.48-0.51 of the normal speed even at 20 mm per step.
_WALL_TRAVEL_FACTOR = 2.0
# A ball falling faster than this (m/s) can bounce on the surface; slower, it rolls or rests.
_FALLING = 0.3


def _angle_between(a: float, b: float) -> float:
    """|a - b| wrapped into [0, pi]."""
    d = (a - b) % (2 * math.pi)
    return 2 * math.pi - d if d > math.pi else d


def _distance_to_leg_sweep(rho: float, phi: float, spin: float, sweep: float) -> float:
    """Distance from a point (polar: ``rho`` from the axis, at angle ``phi``) to everywhere a
    figurine's leg goes while its spin angle moves within ``spin`` +- ``sweep``."""
    half = sweep + _LEG_HALF_ANGLE
    off = _angle_between(phi, spin)
    if off <= half or half >= math.pi:
        return max(0.0, rho - _LEG_OUTER, _LEG_INNER - rho)
    # Outside the swept sector: the nearest point is on one of its two edges.
    a = off - half
    along, across = rho * math.cos(a), rho * math.sin(a)
    if along < _LEG_INNER:
        return math.hypot(_LEG_INNER - along, across)
    if along > _LEG_OUTER:
        return math.hypot(along - _LEG_OUTER, across)
    return rho * math.sin(a)


class TableSim:
    """A foosball table in PyBullet.

    Args:
        rods: names of the rods in play (see ``foosball_gym.table.RODS``), in the order every
            joint array of this class uses.
        physics_hz: physics step rate away from contacts (240); a whole multiple of
            ``control_hz``.
        control_hz: control steps per second (60): one :meth:`step` is ``1 / control_hz``.
        contact_travel: near a possible contact, physics steps are made fine enough that the
            ball moves at most this far (m) relative to what it may touch within one.
        rolling_resistance: how a rolling ball slows, as a deceleration in units of g.
        gui: open the PyBullet GUI instead of running headless.
        slide_gain, spin_gain: position gains of the simulated drives (1/s: the speed a drive
            asks for per unit of position error). The defaults reach a 0.1 m slide target in
            about 90 ms without overshoot.
    """

    def __init__(
        self,
        rods: Sequence[str],
        *,
        physics_hz: int = T.PHYSICS_HZ,
        control_hz: int = T.CONTROL_HZ,
        contact_travel: float = T.CONTACT_TRAVEL,
        rolling_resistance: float = T.ROLLING_RESISTANCE,
        gui: bool = False,
        slide_gain: float = 48.0,
        spin_gain: float = 72.0,
    ) -> None:
        physics_hz, control_hz, contact_travel, rolling_resistance = check_physics(
            physics_hz, control_hz, contact_travel, rolling_resistance
        )
        names = tuple(rods)
        for name in names:
            T.rod(name)
        if len(set(names)) != len(names):
            raise ValueError(f"each rod may be in play once, got {names}")
        self.rods: tuple[T.Rod, ...] = tuple(T.rod(n) for n in names)
        self.physics_hz = physics_hz
        self.control_hz = control_hz
        self.substeps = physics_hz // control_hz
        self.control_dt = 1.0 / control_hz
        self.contact_travel = contact_travel
        self.gui = gui
        self._closed = True
        if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            raise RuntimeError(
                "the PyBullet GUI (render_mode='human') needs a display and "
                "DISPLAY is not set; on a headless machine use "
                "render_mode='rgb_array', or run under xvfb-run"
            )
        with _quiet_stdout():
            self._client = BulletClient(pybullet.GUI if gui else pybullet.DIRECT)
        self._closed = False
        self._p = self._client
        # BulletClient builds a new partial on every attribute access; the calls made every
        # physics step are bound once here instead.
        cid = self._client._client
        self._step_sim = functools.partial(pybullet.stepSimulation, physicsClientId=cid)
        self._base_pose = functools.partial(
            pybullet.getBasePositionAndOrientation, physicsClientId=cid
        )
        self._base_vel = functools.partial(pybullet.getBaseVelocity, physicsClientId=cid)
        self._joint_states = functools.partial(pybullet.getJointStates, physicsClientId=cid)
        self._motor_array = functools.partial(
            pybullet.setJointMotorControlArray, physicsClientId=cid
        )
        self._set_engine = functools.partial(
            pybullet.setPhysicsEngineParameter, physicsClientId=cid
        )
        self._p.setGravity(0, 0, -9.81)
        self._dt = 1.0 / physics_hz
        self._p.setPhysicsEngineParameter(
            fixedTimeStep=self._dt,
            numSubSteps=0,
            deterministicOverlappingPairs=1,
            erp=_ERP_RATE * self._dt,
            contactERP=_ERP_RATE * self._dt,
        )
        if gui:
            self._p.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0)
            # Shadows add nothing to a view from above, and a software renderer (a virtual
            # display) drawing them held every call to the simulator up by 28 ms.
            self._p.configureDebugVisualizer(pybullet.COV_ENABLE_SHADOWS, 0)
            # Looking down with the home goal on the left: the screen's right is +x, its up +y.
            self._p.resetDebugVisualizerCamera(1.1, 0, -89.9, [0, 0, 0])
        self._text_items: list[tuple[str, int]] = []
        self._keyboard_taken = False
        with _quiet_stdout():
            self.body = self._p.loadURDF(_urdf_with_rods(names), useFixedBase=True)
        joint_index = {}
        for i in range(self._p.getNumJoints(self.body)):
            info = self._p.getJointInfo(self.body, i)
            joint_index[info[1].decode()] = i
        self._slide_idx = [joint_index[r.slide_joint] for r in self.rods]
        self._spin_idx = [joint_index[r.spin_joint] for r in self.rods]
        self._joint_idx = self._slide_idx + self._spin_idx
        self._n = len(self.rods)
        self._max_force = [T.SLIDE_MAX_FORCE] * self._n + [T.SPIN_MAX_TORQUE] * self._n
        self._max_speed = [T.SLIDE_MAX_SPEED] * self._n + [T.SPIN_MAX_SPEED] * self._n
        self._lower = [-r.slide_limit for r in self.rods] + [-T.SPIN_LIMIT] * self._n
        self._upper = [-v for v in self._lower]
        self._accel = [drive_acceleration(r, "slide") for r in self.rods] + [
            drive_acceleration(r, "spin") for r in self.rods
        ]
        self.set_drive_gains(slide_gain, spin_gain)

        # Bullet keeps one friction and one restitution per body and multiplies two bodies'
        # values; the authors' engine averages them. The ball is the only body that touches
        # anything, so it carries 1 and each body it can touch carries the value of its
        # contact with the ball (table.py: BALL_TABLE_*, BALL_FIGURINE_*): see
        # _apply_ball_dynamics.
        self._p.changeDynamics(self.body, -1, maxJointVelocity=T.SPIN_MAX_SPEED * 1.1)
        for idx in self._joint_idx:
            self._p.changeDynamics(
                self.body, idx, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0
            )
        self._mode = "position"
        self._targets = [0.0] * (2 * self._n)
        self._velocity_targets = [0.0] * (2 * self._n)
        self._sent_dt = 0.0
        # What the last reads of the ball and the joints gave, until the world moves.
        self._ball_cache: tuple[float, float, float, float, float, float] | None = None
        self._joint_cache: tuple[tuple[float, ...], tuple[float, ...]] | None = None
        self._init_motors()

        self.ball_mass = T.BALL_MASS
        self.ball_friction = T.BALL_MATERIAL.dynamic_friction
        self.ball_restitution = T.BALL_TABLE_RESTITUTION
        self.ball_damping = T.BALL_LINEAR_DAMPING
        self.rolling_resistance = rolling_resistance
        self._spawn_ball()
        self._camera: CameraModel | None = None
        self._view = self._proj = None
        self._shapes: list[tuple[int, int, int, list[float]]] | None = None
        self._fixed_shown = True
        self._fixed_layers: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self.physics_steps = 0

    # ----------------------------------------------------------------------------- set-up

    def set_drive_gains(self, slide_gain: float, spin_gain: float) -> None:
        """Position gains of the simulated drives in 1/s (used in position mode)."""
        if not (slide_gain > 0 and spin_gain > 0) or not math.isfinite(slide_gain + spin_gain):
            raise ValueError(f"drive gains must be positive, got {slide_gain}, {spin_gain}")
        self.slide_gain, self.spin_gain = float(slide_gain), float(spin_gain)
        self._gains_per_s = [self.slide_gain] * self._n + [self.spin_gain] * self._n
        self._sent_dt = 0.0  # the next step sends the new gains

    def _init_motors(self) -> None:
        # The speed clamp set here stays with Bullet's motor; later array commands keep it.
        for idx, force, speed in zip(self._joint_idx, self._max_force, self._max_speed):
            self._p.setJointMotorControl2(
                self.body,
                idx,
                pybullet.POSITION_CONTROL,
                targetPosition=0.0,
                force=force,
                maxVelocity=speed,
            )

    def set_ball_dynamics(
        self,
        *,
        mass: float | None = None,
        friction: float | None = None,
        restitution: float | None = None,
        linear_damping: float | None = None,
        rolling_resistance: float | None = None,
    ) -> None:
        """Change the ball's physical parameters (domain randomisation); None keeps a value.

        Args:
            mass: kg.
            friction: the ball material's friction; each contact averages it with the other
                material's, as the authors' engine does.
            restitution: the restitution of every contact the ball makes.
            linear_damping: Bullet's linear damping of the ball.
            rolling_resistance: deceleration of a rolling ball in units of g.
        """
        values = {
            "mass": mass,
            "friction": friction,
            "restitution": restitution,
            "linear_damping": linear_damping,
            "rolling_resistance": rolling_resistance,
        }
        for key, value in values.items():
            if value is not None and (not math.isfinite(value) or value < 0):
                raise ValueError(f"ball {key} must be a finite non-negative number, got {value}")
        if mass is not None and mass <= 0:
            raise ValueError(f"ball mass must be positive, got {mass}")
        if restitution is not None and restitution > 1:
            raise ValueError(f"ball restitution must be in [0, 1], got {restitution}")
        self.ball_mass = self.ball_mass if mass is None else float(mass)
        self.ball_friction = self.ball_friction if friction is None else float(friction)
        self.ball_restitution = self.ball_restitution if restitution is None else float(restitution)
        self.ball_damping = self.ball_damping if linear_damping is None else float(linear_damping)
        if rolling_resistance is not None:
            self.rolling_resistance = float(rolling_resistance)
        self._apply_ball_dynamics()

    def _apply_ball_dynamics(self) -> None:
        table_friction = T.combine(self.ball_friction, T.TABLE_MATERIAL.dynamic_friction)
        # The ball on a figurine departs from the authors' average (table.py says why); a
        # randomised ball friction scales it in proportion.
        figurine_friction = (
            T.BALL_FIGURINE_FRICTION * self.ball_friction / T.BALL_MATERIAL.dynamic_friction
        )
        self._p.changeDynamics(
            self.body, -1, lateralFriction=table_friction, restitution=T.TABLE_MATERIAL.restitution
        )
        for idx in self._spin_idx:
            self._p.changeDynamics(
                self.body,
                idx,
                lateralFriction=figurine_friction,
                restitution=T.FIGURINE_MATERIAL.restitution,
            )
        # A rolling resistance torque mu * N slows a rolling solid sphere by (5/7) g mu / r;
        # Bullet's torque coefficient for the ball on the table is the ball's rolling friction
        # times the table's friction.
        rolling = 1.4 * self.rolling_resistance * T.BALL_RADIUS / table_friction
        self._p.changeDynamics(
            self.ball,
            -1,
            mass=self.ball_mass,
            lateralFriction=1.0,
            restitution=self.ball_restitution / T.TABLE_MATERIAL.restitution,
            rollingFriction=rolling,
            linearDamping=self.ball_damping,
            angularDamping=0.0,
            ccdSweptSphereRadius=0.0,
        )

    def _spawn_ball(self) -> None:
        with _quiet_stdout():
            self.ball = self._p.loadURDF(
                str(urdf_path("ball.urdf")), [0.0, 0.0, T.BALL_RADIUS], useMaximalCoordinates=True
            )
        self._apply_ball_dynamics()

    # ----------------------------------------------------------------------------- state

    def reset(
        self,
        slide: Sequence[float] | None = None,
        spin: Sequence[float] | None = None,
        ball_position: Sequence[float] = (0.0, 0.0),
        ball_velocity: Sequence[float] = (0.0, 0.0),
    ) -> None:
        """Put the rods and the ball in a state, all at rest except the ball.

        Args:
            slide, spin: joint values per rod in play (default 0).
            ball_position, ball_velocity: see :meth:`place_ball`.
        """
        # One step with the ball alone, high above the table, clears what Bullet carries in the
        # ball from step to step (cached contacts, solver impulses): without it a reset state
        # plays out a hair (1e-34) differently from the same state in a new table.
        self._p.resetBasePositionAndOrientation(self.ball, [0.0, 0.0, 5.0], [0.0, 0.0, 0.0, 1.0])
        self._p.resetBaseVelocity(self.ball, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        self._set_step(1.0 / self.physics_hz)
        self._step_sim()
        self._ball_cache = self._joint_cache = None
        slide = np.zeros(self._n) if slide is None else np.asarray(slide, dtype=float)
        spin = np.zeros(self._n) if spin is None else np.asarray(spin, dtype=float)
        if slide.shape != (self._n,) or spin.shape != (self._n,):
            raise ValueError(f"slide and spin need one value per rod in play ({self._n})")
        for idx, value in zip(self._joint_idx, np.concatenate([slide, spin])):
            self._p.resetJointState(self.body, idx, float(value), 0.0)
        self._joint_cache = None
        self.place_ball(ball_position, ball_velocity)
        self.command("position", [*slide, *spin])

    def place_ball(
        self,
        position: Sequence[float],
        velocity: Sequence[float] = (0.0, 0.0),
        *,
        rolling: bool = False,
    ) -> None:
        """Put the ball somewhere, leaving the rods as they are (a serve in a running game).

        Args:
            position: (x, y) on the surface, or (x, y, z).
            velocity: (vx, vy) or (vx, vy, vz). The ball starts without spin, sliding, as a
                shot leaves a foot: the table's friction makes it roll within a few metres. (A
                ball given the spin of rolling at 15 m/s climbs a wall it meets: friction on
                its spinning face threw it 0.26 m up.)
            rolling: start with the spin of rolling without slipping instead.
        """
        pos = [float(v) for v in position]
        vel = [float(v) for v in velocity]
        if len(pos) == 2:
            pos.append(T.BALL_RADIUS)
        if len(vel) == 2:
            vel.append(0.0)
        if len(pos) != 3 or len(vel) != 3:
            raise ValueError("ball position and velocity take 2 (x, y) or 3 (x, y, z) values")
        self._p.resetBasePositionAndOrientation(self.ball, pos, [0.0, 0.0, 0.0, 1.0])
        spin = [-vel[1] / T.BALL_RADIUS, vel[0] / T.BALL_RADIUS, 0.0] if rolling else [0.0] * 3
        self._p.resetBaseVelocity(self.ball, vel, spin)
        self._ball_cache = None

    def command(self, mode: str, targets: Sequence[float]) -> None:
        """Set the drives' targets for every joint in play.

        Args:
            mode: ``"position"`` (metres, radians; clamped to the joint limits),
                ``"velocity"`` (m/s, rad/s; clamped to the drives' speed) or ``"torque"``
                (N, N m; clamped to the drives' force and torque).
            targets: one per joint in play: every rod's slide, then every rod's spin.
        """
        if mode != self._mode:
            if mode not in CONTROL_MODES:
                raise ValueError(
                    f"unknown control mode {mode!r}; allowed: {', '.join(CONTROL_MODES)}"
                )
            if mode == "torque":
                # Bullet's joint motors must let go before raw torques can move the joints.
                self._p.setJointMotorControlArray(
                    self.body,
                    self._joint_idx,
                    pybullet.VELOCITY_CONTROL,
                    forces=[0.0] * (2 * self._n),
                )
            self._mode = mode
        if len(targets) != 2 * self._n:
            raise ValueError(f"need {2 * self._n} targets (slides, then spins), got {len(targets)}")
        if mode == "position":
            self._targets = [
                lo if t < lo else hi if t > hi else t
                for t, lo, hi in zip(targets, self._lower, self._upper)
            ]
            self._send_position(self._dt)
        elif mode == "velocity":
            clipped = [
                -m if t < -m else m if t > m else t for t, m in zip(targets, self._max_speed)
            ]
            self._velocity_targets = clipped
            self._motor_array(
                self.body,
                self._joint_idx,
                pybullet.VELOCITY_CONTROL,
                targetVelocities=clipped,
                forces=self._max_force,
            )
        else:
            self._torques = [
                -m if t < -m else m if t > m else t for t, m in zip(targets, self._max_force)
            ]

    def _send_position(self, dt: float) -> None:
        # Bullet's position gain is per physics step: the speed it asks for is gain * error / dt.
        self._motor_array(
            self.body,
            self._joint_idx,
            pybullet.POSITION_CONTROL,
            targetPositions=self._targets,
            forces=self._max_force,
            positionGains=[g * dt for g in self._gains_per_s],
        )
        self._sent_dt = dt

    def step(self) -> tuple[int, bool]:
        """Advance one control step.

        Returns:
            ``(goal, out_of_table)``: goal is :data:`HOME_SCORED`, :data:`AWAY_SCORED` or
            :data:`NO_GOAL`. Stepping stops at the physics step where either event happens.
        """
        steps, figurine = self._steps_needed(self.control_dt)
        if not figurine or steps <= 2 * self.substeps:
            return self._advance(self.control_dt, steps)
        # A figurine may meet the ball fast: decide again for each base step, over which a drive
        # moves a figurine far less than over a whole control step, so fewer are fine.
        base = 1.0 / self.physics_hz
        for _ in range(self.substeps):
            steps, _ = self._steps_needed(base)
            result = self._advance(base, steps)
            if result != (NO_GOAL, False):
                return result
        return NO_GOAL, False

    def _advance(self, duration: float, steps: int) -> tuple[int, bool]:
        """Step ``duration`` seconds in ``steps`` equal physics steps, watching for goals."""
        self._set_step(duration / steps)
        self._ball_cache = self._joint_cache = None
        step, pose, ball = self._step_sim, self._base_pose, self.ball
        torque = self._mode == "torque"
        line, half = T.GOAL_LINE_X, T.GOAL_HALF_WIDTH
        self.physics_steps += steps
        for _ in range(steps):
            if torque:
                self._motor_array(
                    self.body, self._joint_idx, pybullet.TORQUE_CONTROL, forces=self._torques
                )
            step()
            (x, y, z), _ = pose(ball)
            if (x > line or x < -line) and -half <= y <= half:
                return (HOME_SCORED if x > 0 else AWAY_SCORED), False
            if z > T.OUT_OF_TABLE_HEIGHT:
                return NO_GOAL, True
        return NO_GOAL, False

    def _set_step(self, dt: float) -> None:
        if dt != self._dt:
            erp = _ERP_RATE * dt
            self._set_engine(fixedTimeStep=dt, erp=erp, contactERP=erp)
            self._dt = dt
        if self._mode == "position" and dt != self._sent_dt:
            self._send_position(dt)

    def _steps_needed(self, dt: float) -> tuple[int, bool]:
        """Physics steps for the next ``dt`` seconds, and whether a figurine may meet the ball
        within them: one step per base step unless the ball could touch a wall or a figurine,
        else enough that nothing it could touch moves more than ``contact_travel`` relative to
        it per step."""
        least = max(1, round(dt * self.physics_hz))
        x, y, z, _, _, vz = ball = self._ball()
        speed = math.sqrt(ball[3] * ball[3] + ball[4] * ball[4] + vz * vz)
        reach = speed * dt + _NEAR_MARGIN + T.BALL_RADIUS
        wall = (
            T.FIELD_HALF_WIDTH - abs(y) < reach
            or T.FIELD_HALF_LENGTH - abs(x) < reach
            or (vz < -_FALLING and z < reach)
        )
        figurine = 0.0
        dz = z - T.ROD_HEIGHT
        joints = None
        for i, rod in enumerate(self.rods):
            dx = x - rod.x
            rho = math.sqrt(dx * dx + dz * dz)
            if rho - reach > _LEG_OUTER:
                continue  # beyond the reach of the rod's figurines at any spin
            if joints is None:
                joints = self._joints()
            pos, vel = joints
            v = self._speed_bound(i, pos, vel, dt)
            w = self._speed_bound(self._n + i, pos, vel, dt)
            if rho - reach >= _BODY_REACH:
                phi = math.atan2(rod.direction * dx, -dz)
                if _distance_to_leg_sweep(rho, phi, pos[self._n + i], w * dt) >= reach:
                    continue
            gap = reach + v * dt + _FIGURINE_HALF_WIDTH
            slide, d = pos[i], rod.direction
            if any(abs(d * (slide + off) - y) < gap for off in rod.figurine_offsets):
                figurine = max(figurine, v + w * _LEG_OUTER)
        if not figurine:
            if not wall:
                return least, False
            # A wall is flat: how deep the ball gets in before it bounces does not turn the
            # bounce, so walls alone need only half the resolution of a figurine's round end.
            travel = _WALL_TRAVEL_FACTOR * self.contact_travel
            return max(least, math.ceil(min(speed, T.RESOLVED_SPEED) * dt / travel)), False
        # A kick can send the ball off at (1 + restitution) times the foot's speed on top of
        # its own, and it may then meet anything else within the same control step.
        relative = speed + (1 + T.BALL_FIGURINE_RESTITUTION) * figurine
        # Faster than the spec's fastest ball only a foot swinging at full speed goes; it is
        # resolved as coarsely as a 20 m/s ball, so a step's travel grows with its speed.
        relative = min(relative, T.RESOLVED_SPEED)
        return max(least, math.ceil(relative * dt / self.contact_travel)), True

    def _speed_bound(self, j: int, pos: Sequence[float], vel: Sequence[float], dt: float) -> float:
        """The fastest joint ``j`` can move within the next ``dt`` seconds.

        A position drive asks for gain * error (clamped to its top speed) and gets there from
        the speed it has, so its speed stays between the two; a velocity drive likewise with
        its target. Under torque control only the drive's top speed bounds it. Either way its
        force or torque adds at most ``accel * dt``: a five-figurine rod gains at most 32 rad/s
        in a 240 Hz step. The slack covers a drive overshooting the speed it asks for.
        """
        now = abs(vel[j])
        top = self._max_speed[j]
        if self._mode == "position":
            asked = self._gains_per_s[j] * abs(self._targets[j] - pos[j])
        elif self._mode == "velocity":
            asked = abs(self._velocity_targets[j])
        else:
            asked = top
        reachable = now + self._accel[j] * dt
        return min(top, 1.2 * max(now, min(asked, reachable)) + 0.02 * top)

    def _ball(self) -> tuple[float, float, float, float, float, float]:
        if self._ball_cache is None:
            (x, y, z), _ = self._base_pose(self.ball)
            (vx, vy, vz), _ = self._base_vel(self.ball)
            self._ball_cache = (x, y, z, vx, vy, vz)
        return self._ball_cache

    def _joints(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        if self._joint_cache is None:
            states = self._joint_states(self.body, self._joint_idx)
            self._joint_cache = tuple(s[0] for s in states), tuple(s[1] for s in states)
        return self._joint_cache

    def joint_states(self) -> tuple[list[float], list[float]]:
        """Positions and velocities of every joint in play: slides first, then spins."""
        pos, vel = self._joints()
        return list(pos), list(vel)

    def ball_state(self) -> BallState:
        x, y, z, vx, vy, vz = self._ball()
        return BallState(np.array([x, y, z]), np.array([vx, vy, vz]))

    def ball_xy(self) -> tuple[float, float, float, float]:
        """Ball x, y, vx, vy: the four ball numbers every observation holds."""
        x, y, _, vx, vy, _ = self._ball()
        return x, y, vx, vy

    def scene(self) -> tuple[list[float], list[float]]:
        """What a picture of the table shows: joint positions (slides, then spins) and the
        ball's x, y, z. :meth:`show` puts another table into it."""
        x, y, z, _, _, _ = self._ball()
        return list(self._joints()[0]), [x, y, z]

    def show(self, positions: Sequence[float], ball: Sequence[float]) -> None:
        """Pose the rods and the ball as :meth:`scene` gave them, at rest, for rendering."""
        if len(positions) != len(self._joint_idx) or len(ball) != 3:
            raise ValueError(
                f"show needs {len(self._joint_idx)} joint positions and the ball's x, y, z"
            )
        for idx, value in zip(self._joint_idx, positions):
            self._p.resetJointState(self.body, idx, float(value), 0.0)
        self._p.resetBasePositionAndOrientation(self.ball, [float(v) for v in ball], [0, 0, 0, 1])
        self._ball_cache = self._joint_cache = None

    # ----------------------------------------------------------------------------- the GUI

    def show_text(self, lines: Sequence[str]) -> None:
        """Write ``lines`` in the GUI window, the first above the table and the others below
        it, replacing what the last call wrote; without the GUI, nothing."""
        if not self.gui:
            return
        lines = list(lines)
        for i, line in enumerate(lines):
            shown = self._text_items[i] if i < len(self._text_items) else None
            if shown is not None and shown[0] == line:
                continue
            beyond = T.FIELD_HALF_WIDTH + _TEXT_MARGIN
            y = beyond if i == 0 else -(beyond + (i - 1) * _TEXT_LINE)
            item = self._p.addUserDebugText(
                line,
                [-T.FIELD_HALF_LENGTH, y, 0.1],
                textColorRGB=[0, 0, 0],
                textSize=1.5,
                replaceItemUniqueId=shown[1] if shown is not None else -1,
            )
            if shown is None:
                self._text_items.append((line, item))
            else:
                self._text_items[i] = (line, item)
        for _, item in self._text_items[len(lines) :]:
            self._p.removeUserDebugItem(item)
        del self._text_items[len(lines) :]

    def keyboard_events(self) -> tuple[frozenset[str], frozenset[str]]:
        """The keys held down in the GUI window now, and those pressed since the last call.

        Keys are named ``"left"``, ``"right"``, ``"up"``, ``"down"``, ``"space"``,
        ``"return"`` or by their lower-case character. The first call turns off the GUI's
        own single-key shortcuts (wireframe, ...), which would fight a player's keys.
        Without the GUI there are no keys.
        """
        if not self.gui:
            return frozenset(), frozenset()
        if not self._keyboard_taken:
            self._p.configureDebugVisualizer(pybullet.COV_ENABLE_KEYBOARD_SHORTCUTS, 0)
            self._keyboard_taken = True
        held, pressed = set(), set()
        for code, state in self._p.getKeyboardEvents().items():
            name = _KEY_NAMES.get(code) or (chr(code).lower() if 32 < code < 127 else None)
            if name is None:
                continue
            if state & pybullet.KEY_IS_DOWN:
                held.add(name)
            if state & pybullet.KEY_WAS_TRIGGERED:
                pressed.add(name)
        return frozenset(held), frozenset(pressed)

    def figurine_positions(self) -> np.ndarray:
        """World centres of every figurine on the rods in play, (N, 3), rod by rod."""
        pos, _ = self.joint_states()
        return figurine_centres(self.rods, pos[: self._n], pos[self._n :])

    # ----------------------------------------------------------------------------- output

    def camera(self, width: int, height: int) -> CameraModel:
        if self._camera is None or (self._camera.width, self._camera.height) != (width, height):
            cam = CameraModel(width, height)
            self._camera = cam
            self._view = self._p.computeViewMatrix(
                [0, 0, cam.height_above_table], [0, 0, 0], [0, 1, 0]
            )
            self._proj = self._p.computeProjectionMatrixFOV(
                cam.vertical_fov_deg, width / height, 0.1, cam.height_above_table + 0.5
            )
        return self._camera

    def render(self, width: int = 320, height: int = 180, layered: bool = True) -> np.ndarray:
        """An (height, width, 3) uint8 top view from the CPU renderer.

        ``layered`` draws the table's fixed parts once per size and then only the rods and
        the ball, laid over them by depth: the same picture (a test compares them pixel for
        pixel) in a quarter of the time for one rod, since the field and walls fill most of
        the frame. Without a GUI only: there the fixed parts must stay on the screen.
        """
        if width <= 0 or height <= 0:
            raise ValueError(f"image size must be positive, got {width}x{height}")
        self.camera(width, height)
        if not layered or self.gui:
            self._show_fixed_parts(True)
            return self._draw(width, height)[0]
        fixed_rgb, fixed_depth = self._fixed_layer(width, height)
        self._show_fixed_parts(False)
        rgb, depth = self._draw(width, height)
        return np.where((depth < fixed_depth)[:, :, None], rgb, fixed_rgb)

    def _draw(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        _, _, rgba, depth, _ = self._p.getCameraImage(
            width,
            height,
            self._view,
            self._proj,
            renderer=pybullet.ER_TINY_RENDERER,
            shadow=0,
            flags=pybullet.ER_NO_SEGMENTATION_MASK,
        )
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()
        return rgb, np.asarray(depth, dtype=np.float32).reshape(height, width)

    def _visual_shapes(self) -> list[tuple[int, int, int, list[float]]]:
        """(body, link, shape index, colour) of every visual shape, fixed parts first."""
        if self._shapes is None:
            shapes, seen = [], collections.Counter()
            for body in (self.body, self.ball):
                for shape in self._p.getVisualShapeData(body):
                    link = shape[1]
                    shapes.append((body, link, seen[body, link], list(shape[7])))
                    seen[body, link] += 1
            self._shapes = shapes
        return self._shapes

    def _set_visible(self, fixed: bool, visible: bool) -> None:
        for body, link, index, colour in self._visual_shapes():
            if (body == self.body and link == -1) == fixed:
                alpha = colour[3] if visible else 0.0
                self._p.changeVisualShape(
                    body, link, shapeIndex=index, rgbaColor=[*colour[:3], alpha]
                )

    def _show_fixed_parts(self, visible: bool) -> None:
        if self._fixed_shown != visible:
            self._set_visible(fixed=True, visible=visible)
            self._fixed_shown = visible

    def _fixed_layer(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """The field and walls alone, with their depth, drawn once per size."""
        layer = self._fixed_layers.get((width, height))
        if layer is None:
            self._show_fixed_parts(True)
            self._set_visible(fixed=False, visible=False)
            try:
                layer = self._draw(width, height)
            finally:
                self._set_visible(fixed=False, visible=True)
            self._fixed_layers[width, height] = layer
        return layer

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            with contextlib.suppress(Exception):
                self._client.disconnect()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()


def figurine_centres(
    rods: Sequence[T.Rod], slide: Sequence[float], spin: Sequence[float]
) -> np.ndarray:
    """World centres of the figurines of ``rods`` for given joint values, (N, 3)."""
    out = []
    for rod, s, a in zip(rods, slide, spin):
        x, z = rod.figurine_swing(a)
        out += [(x, y, z) for y in rod.figurine_y(s)]
    return np.array(out, dtype=float).reshape(-1, 3)
