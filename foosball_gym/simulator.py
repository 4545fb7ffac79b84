"""The simulated table: the only module that imports pybullet.

A :class:`TableSim` owns one ``BulletClient`` (so many tables live in one process), loads the
table URDF with the rods that are in play and the ball, and advances the world in control
steps of several physics substeps. Goals and a ball leaving the table are checked after every
substep, so a fast ball cannot cross the goal line and bounce back out unseen.

Rods that are not in play are left out of the loaded model: they cannot touch the ball and cost
nothing to simulate.
"""

from __future__ import annotations

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
    text = ET.tostring(robot, encoding="unicode")
    # Named by content, so processes share one file and a changed table gets a new one.
    digest = hashlib.sha1(text.encode()).hexdigest()[:16]
    path = Path(tempfile.gettempdir()) / f"foosball_gym_{digest}.urdf"
    if not path.exists():
        fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".urdf")
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    return str(path)


@dataclass
class BallState:
    position: np.ndarray  # (3,) metres
    velocity: np.ndarray  # (3,) m/s


class TableSim:
    """A foosball table in PyBullet.

    Args:
        rods: names of the rods in play (see ``foosball_gym.table.RODS``), in the order every
            joint array of this class uses.
        physics_hz: physics step rate.
        substeps: physics steps per control step.
        gui: open the PyBullet GUI instead of running headless.
        slide_gain, spin_gain: position gains of the simulated drives (Bullet's motor ``kp``).
            The defaults reach a 0.1 m slide target in about 90 ms without overshoot.
    """

    def __init__(
        self,
        rods: Sequence[str],
        *,
        physics_hz: int = T.PHYSICS_HZ,
        substeps: int = T.PHYSICS_HZ // T.CONTROL_HZ,
        gui: bool = False,
        slide_gain: float = 0.2,
        spin_gain: float = 0.3,
    ) -> None:
        if physics_hz <= 0 or substeps <= 0:
            raise ValueError(
                f"physics_hz and substeps must be positive, got {physics_hz}, {substeps}"
            )
        names = tuple(rods)
        for name in names:
            T.rod(name)
        if len(set(names)) != len(names):
            raise ValueError(f"each rod may be in play once, got {names}")
        self.rods: tuple[T.Rod, ...] = tuple(T.rod(n) for n in names)
        self.physics_hz = physics_hz
        self.substeps = substeps
        self.control_dt = substeps / physics_hz
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
        # substep are bound once here instead.
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
        self._p.setGravity(0, 0, -9.81)
        # allowedCcdPenetration=0: Bullet's default lets a continuous-collision hit sink 4 cm
        # into a wall before it counts; with 0 a ball never sinks more than 2 mm.
        self._p.setPhysicsEngineParameter(
            fixedTimeStep=1.0 / physics_hz,
            numSubSteps=0,
            deterministicOverlappingPairs=1,
            allowedCcdPenetration=0.0,
        )
        if gui:
            self._p.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0)
            self._p.resetDebugVisualizerCamera(1.1, 0, -89.9, [0, 0, 0])
        with _quiet_stdout():
            self.body = self._p.loadURDF(
                _urdf_with_rods(names), useFixedBase=True, flags=pybullet.URDF_MERGE_FIXED_LINKS
            )
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
        self.set_drive_gains(slide_gain, spin_gain)

        self._p.changeDynamics(
            self.body, -1, lateralFriction=T.SURFACE_FRICTION, restitution=T.SURFACE_RESTITUTION
        )
        # Bullet caps every joint speed of a multibody at 100 by default; the spin drive is faster.
        self._p.changeDynamics(self.body, -1, maxJointVelocity=T.SPIN_MAX_SPEED * 1.1)
        for idx in self._spin_idx:
            self._p.changeDynamics(
                self.body,
                idx,
                lateralFriction=T.FIGURINE_FRICTION,
                restitution=T.FIGURINE_RESTITUTION,
            )
        for idx in self._joint_idx:
            self._p.changeDynamics(
                self.body, idx, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0
            )
        self._mode = "position"
        self._init_motors()

        self.ball_mass = T.BALL_MASS
        self.ball_friction = T.BALL_FRICTION
        self.ball_restitution = T.BALL_RESTITUTION
        self.ball_damping = T.BALL_LINEAR_DAMPING
        self._spawn_ball()
        self._camera: CameraModel | None = None
        self._view = self._proj = None

    # ----------------------------------------------------------------------------- set-up

    def set_drive_gains(self, slide_gain: float, spin_gain: float) -> None:
        """Position gains of the simulated drives (used in position mode)."""
        if slide_gain <= 0 or spin_gain <= 0:
            raise ValueError(f"drive gains must be positive, got {slide_gain}, {spin_gain}")
        self.slide_gain, self.spin_gain = float(slide_gain), float(spin_gain)
        self._gains = [self.slide_gain] * self._n + [self.spin_gain] * self._n

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
    ) -> None:
        """Change the ball's physical parameters (domain randomisation); None keeps a value."""
        values = {
            "mass": mass,
            "friction": friction,
            "restitution": restitution,
            "linear_damping": linear_damping,
        }
        for key, value in values.items():
            if value is not None and (not math.isfinite(value) or value < 0):
                raise ValueError(f"ball {key} must be a finite non-negative number, got {value}")
        if mass is not None and mass <= 0:
            raise ValueError(f"ball mass must be positive, got {mass}")
        self.ball_mass = self.ball_mass if mass is None else float(mass)
        self.ball_friction = self.ball_friction if friction is None else float(friction)
        self.ball_restitution = self.ball_restitution if restitution is None else float(restitution)
        self.ball_damping = self.ball_damping if linear_damping is None else float(linear_damping)
        self._apply_ball_dynamics()

    def _apply_ball_dynamics(self) -> None:
        self._p.changeDynamics(
            self.ball,
            -1,
            mass=self.ball_mass,
            lateralFriction=self.ball_friction,
            # Bullet multiplies the restitution of the two bodies in contact. Every material of
            # the spec bounces with 0.5, so a ball contact should too: the ball carries
            # restitution / 0.5 and everything it can touch carries 0.5. Friction keeps
            # Bullet's product of the spec's values (0.05 on the table, 0.02 on figurines);
            # averaged values (0.3) make a rolling ball climb the side walls at 5 m/s.
            restitution=self.ball_restitution / T.SURFACE_RESTITUTION,
            linearDamping=self.ball_damping,
            angularDamping=0.0,
            # A sphere a little smaller than the ball, so the sweep does not touch the floor.
            ccdSweptSphereRadius=0.9 * T.BALL_RADIUS,
        )

    def _spawn_ball(self) -> None:
        # Maximal coordinates plus a swept sphere give continuous collision detection, so a
        # 15 m/s ball cannot jump through a figurine between two 240 Hz steps.
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
        # ball from step to step (cached contacts, split-impulse velocities): without it a
        # reset state plays out a hair (1e-34) differently from the same state in a new table.
        self._p.resetBasePositionAndOrientation(self.ball, [0.0, 0.0, 5.0], [0.0, 0.0, 0.0, 1.0])
        self._p.resetBaseVelocity(self.ball, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        self._step_sim()
        slide = np.zeros(self._n) if slide is None else np.asarray(slide, dtype=float)
        spin = np.zeros(self._n) if spin is None else np.asarray(spin, dtype=float)
        if slide.shape != (self._n,) or spin.shape != (self._n,):
            raise ValueError(f"slide and spin need one value per rod in play ({self._n})")
        for idx, value in zip(self._joint_idx, np.concatenate([slide, spin])):
            self._p.resetJointState(self.body, idx, float(value), 0.0)
        self.place_ball(ball_position, ball_velocity)
        self.command("position", [*slide, *spin])

    def place_ball(self, position: Sequence[float], velocity: Sequence[float] = (0.0, 0.0)) -> None:
        """Put the ball somewhere, leaving the rods as they are (a serve in a running game).

        Args:
            position: (x, y) on the surface, or (x, y, z).
            velocity: (vx, vy) or (vx, vy, vz); the ball is given the spin of rolling without
                slipping, so it does not skid when it starts.
        """
        pos = [float(v) for v in position]
        vel = [float(v) for v in velocity]
        if len(pos) == 2:
            pos.append(T.BALL_RADIUS)
        if len(vel) == 2:
            vel.append(0.0)
        if len(pos) != 3 or len(vel) != 3:
            raise ValueError("ball position and velocity take 2 (x, y) or 3 (x, y, z) values")
        rolling = [-vel[1] / T.BALL_RADIUS, vel[0] / T.BALL_RADIUS, 0.0]
        self._p.resetBasePositionAndOrientation(self.ball, pos, [0.0, 0.0, 0.0, 1.0])
        self._p.resetBaseVelocity(self.ball, vel, rolling)

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
            clipped = [
                lo if t < lo else hi if t > hi else t
                for t, lo, hi in zip(targets, self._lower, self._upper)
            ]
            self._motor_array(
                self.body,
                self._joint_idx,
                pybullet.POSITION_CONTROL,
                targetPositions=clipped,
                forces=self._max_force,
                positionGains=self._gains,
            )
        elif mode == "velocity":
            clipped = [
                -m if t < -m else m if t > m else t for t, m in zip(targets, self._max_speed)
            ]
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

    def step(self) -> tuple[int, bool]:
        """Advance one control step.

        Returns:
            ``(goal, out_of_table)``: goal is :data:`HOME_SCORED`, :data:`AWAY_SCORED` or
            :data:`NO_GOAL`. Stepping stops at the substep where either event happens.
        """
        step, pose, ball = self._step_sim, self._base_pose, self.ball
        torque = self._mode == "torque"
        line, half = T.GOAL_LINE_X, T.GOAL_HALF_WIDTH
        for _ in range(self.substeps):
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

    def joint_states(self) -> tuple[list[float], list[float]]:
        """Positions and velocities of every joint in play: slides first, then spins."""
        states = self._joint_states(self.body, self._joint_idx)
        return [s[0] for s in states], [s[1] for s in states]

    def ball_state(self) -> BallState:
        pos, _ = self._p.getBasePositionAndOrientation(self.ball)
        vel, _ = self._p.getBaseVelocity(self.ball)
        return BallState(np.array(pos), np.array(vel))

    def ball_xy(self) -> tuple[float, float, float, float]:
        """Ball x, y, vx, vy: the four ball numbers every observation holds."""
        (x, y, _), _ = self._base_pose(self.ball)
        (vx, vy, _), _ = self._base_vel(self.ball)
        return x, y, vx, vy

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

    def render(self, width: int = 320, height: int = 180) -> np.ndarray:
        """An (height, width, 3) uint8 top view from the CPU renderer."""
        if width <= 0 or height <= 0:
            raise ValueError(f"image size must be positive, got {width}x{height}")
        self.camera(width, height)
        _, _, rgba, _, _ = self._p.getCameraImage(
            width,
            height,
            self._view,
            self._proj,
            renderer=pybullet.ER_TINY_RENDERER,
            shadow=0,
            flags=pybullet.ER_NO_SEGMENTATION_MASK,
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()

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
    below = T.FIGURINE_CENTRE_BELOW_AXIS
    for rod, s, a in zip(rods, slide, spin):
        d = rod.direction
        # Positive spin swings the part below the axis towards the team's attacking side.
        dx, dz = d * below * math.sin(a), -below * math.cos(a)
        for off in rod.figurine_offsets:
            out.append((rod.x + dx, d * (s + off), T.ROD_HEIGHT + dz))
    return np.array(out, dtype=float).reshape(-1, 3)
