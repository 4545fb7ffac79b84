"""Bullet worlds for the simulated table: with :mod:`foosball_gym.simulator`, the only code
that imports pybullet.

A :class:`World` is one ``BulletClient`` holding the table (surface, walls, goals), some of the
rods and a ball. The simulator keeps a world with no rods, where the ball rolls while no
figurine can reach it, and a world for each pair of neighbouring rods, used while the ball is
near them. A world costs 28 MB and 12 ms to start (its client's buffers), which is why rods
share worlds by pairs instead of each set of rods having one.

Worlds are not shared between tables: Bullet keeps the ball's contacts from step to step to
start its solver from, and a world set up afresh every control step for whichever table used it
last loses them, and a ball pinned under a foot jitters.
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
from functools import cache
from importlib import resources
from pathlib import Path

from foosball_gym import table as T


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


def urdf_path(name: str = "foosball_table.urdf") -> Path:
    """Path of a URDF shipped with the package (``urdf/`` of the source tree)."""
    try:
        return Path(str(resources.files("foosball_gym.urdf") / name))
    except ModuleNotFoundError:
        # A source checkout imported straight from its directory has no mapped subpackage.
        return Path(__file__).resolve().parents[1] / "urdf" / name


@cache
def urdf_with_rods(rod_names: tuple[str, ...]) -> str:
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


# How fast (1/s) Bullet pushes penetrating bodies apart. The velocity it adds also adds to a
# bounce, and for contacts with a multibody (the table, a figurine) it cannot be split off:
# Bullet's 0.2 per step made a wall rebound keep 0.51-0.70 of the normal speed instead of 0.5;
# 0.01 per 240 Hz step keeps 0.48-0.51, and a ball at rest still sits on the surface to 0.01 mm.
# Per second, so that finer steps do not push harder.
ERP_RATE = 0.01 * T.PHYSICS_HZ
# Where a world's ball waits while Bullet forgets its contacts (see World.clear).
_ASIDE = (0.0, 0.0, 5.0)
_STILL = (0.0, 0.0, 0.0)
UPRIGHT = (0.0, 0.0, 0.0, 1.0)
# Where a world's rod that is not simulated waits (a slide, m): its figurines far beside the
# table, out of the ball's way, at rest.
_PARKED = 10.0


def connect(gui: bool = False) -> BulletClient:
    with _quiet_stdout():
        return BulletClient(pybullet.GUI if gui else pybullet.DIRECT)


def _order(names: Sequence[str]) -> tuple[str, ...]:
    """Rod names in the table's order (``table.RODS``), as a world is keyed."""
    rank = {rod.name: k for k, rod in enumerate(T.RODS)}
    return tuple(sorted(names, key=rank.__getitem__))


@cache
def drive_masses(names: tuple[str, ...]) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """What each drive moves (slides' masses, then spins' moments of inertia about their axes)
    and gravity's torque on each spin at a quarter turn, as Bullet holds them for these rods.

    Bullet derives a rod's inertia from its collision shapes, not from the URDF, so it is read
    back from a table loaded once per process.
    """
    client = connect()
    try:
        with _quiet_stdout():
            body = client.loadURDF(urdf_with_rods(names), useFixedBase=True)
        index = {
            client.getJointInfo(body, i)[1].decode(): i for i in range(client.getNumJoints(body))
        }
        slides, spins, gravity = [], [], []
        for name in names:
            rod = T.rod(name)
            carriage = client.getDynamicsInfo(body, index[rod.slide_joint])
            bar = client.getDynamicsInfo(body, index[rod.spin_joint])
            mass, inertia, (cx, _, cz) = bar[0], bar[2], bar[3]
            slides.append(carriage[0] + mass)
            # The spin axis is the link's y axis; its centre of mass hangs off it.
            spins.append(inertia[1] + mass * (cx * cx + cz * cz))
            gravity.append(mass * 9.81 * math.hypot(cx, cz))
        return (*slides, *spins), (0.0,) * len(names) + tuple(gravity)
    finally:
        client.disconnect()


class World:
    """One Bullet world: the table with the rods ``names``, and a ball.

    Which of its rods stand in the table (``placed``; the others wait parked, out of the ball's
    way) and what their motors were told (``sent``) is for the simulator to set.
    """

    def __init__(self, names: Sequence[str], *, gui: bool = False) -> None:
        self.names = _order(names)
        self.client = connect(gui)
        p = self.client
        cid = p._client
        # BulletClient builds a new partial on every attribute access; the calls made every
        # physics step are bound once here instead.
        self.step = functools.partial(pybullet.stepSimulation, physicsClientId=cid)
        self.pose = functools.partial(pybullet.getBasePositionAndOrientation, physicsClientId=cid)
        # A body's bounding box: for the ball, centred on it, and read in half the time of its
        # pose (which copies 30 kB of state for every body).
        self.box = functools.partial(pybullet.getAABB, physicsClientId=cid)
        self.velocity = functools.partial(pybullet.getBaseVelocity, physicsClientId=cid)
        self.reset_pose = functools.partial(
            pybullet.resetBasePositionAndOrientation, physicsClientId=cid
        )
        self.reset_velocity = functools.partial(pybullet.resetBaseVelocity, physicsClientId=cid)
        self.joint_states = functools.partial(pybullet.getJointStates, physicsClientId=cid)
        self.reset_joints = functools.partial(
            pybullet.resetJointStatesMultiDof, physicsClientId=cid
        )
        self.motors = functools.partial(pybullet.setJointMotorControlArray, physicsClientId=cid)
        self.set_engine = functools.partial(pybullet.setPhysicsEngineParameter, physicsClientId=cid)
        p.setGravity(0, 0, -9.81)
        self.dt, self.substeps = 1.0 / T.PHYSICS_HZ, 1
        p.setPhysicsEngineParameter(
            fixedTimeStep=self.dt,
            numSubSteps=0,
            deterministicOverlappingPairs=1,
            erp=ERP_RATE * self.dt,
            contactERP=ERP_RATE * self.dt,
        )
        if gui:
            p.configureDebugVisualizer(pybullet.COV_ENABLE_GUI, 0)
            # Shadows add nothing to a view from above, and a software renderer (a virtual
            # display) drawing them held every call to the simulator up by 28 ms.
            p.configureDebugVisualizer(pybullet.COV_ENABLE_SHADOWS, 0)
            # Looking down with the home goal on the left: the screen's right is +x, its up +y.
            p.resetDebugVisualizerCamera(1.1, 0, -89.9, [0, 0, 0])
        with _quiet_stdout():
            self.body = p.loadURDF(urdf_with_rods(self.names), useFixedBase=True)
        index = {
            p.getJointInfo(self.body, i)[1].decode(): i for i in range(p.getNumJoints(self.body))
        }
        # Each rod's slide and spin link.
        self.links = {
            name: (index[T.rod(name).slide_joint], index[T.rod(name).spin_joint])
            for name in self.names
        }
        p.changeDynamics(self.body, -1, maxJointVelocity=T.SPIN_MAX_SPEED * 1.1)
        for slide, spin in self.links.values():
            for link, force, speed in (
                (slide, T.SLIDE_MAX_FORCE, T.SLIDE_MAX_SPEED),
                (spin, T.SPIN_MAX_TORQUE, T.SPIN_MAX_SPEED),
            ):
                p.changeDynamics(
                    self.body, link, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0
                )
                # The speed clamp set here stays with Bullet's motor; later position commands
                # keep it (a velocity command drops it: see ``unclamped``).
                p.setJointMotorControl2(
                    self.body,
                    link,
                    pybullet.POSITION_CONTROL,
                    targetPosition=0.0,
                    force=force,
                    maxVelocity=speed,
                )
        with _quiet_stdout():
            self.ball = p.loadURDF(
                str(urdf_path("ball.urdf")), [0.0, 0.0, T.BALL_RADIUS], useMaximalCoordinates=True
            )
        self.placed: set[str] = set(self.names)
        for name in self.names:
            self.park(name)
        # Links whose speed clamp a velocity command took away.
        self.unclamped: set[int] = set()
        # What the placed rods' motors were last told (see TableSim._send), and by whom.
        self.sent: tuple | None = None
        self.mode = "position"
        # The ball's and the materials' dynamics last applied (see TableSim._apply_dynamics).
        self.dynamics: tuple | None = None

    def park(self, name: str) -> None:
        """Put rod ``name`` out of the ball's way, at rest, its motors without force (a
        position motor without force sets no constraint and keeps its speed clamp)."""
        links = list(self.links[name])
        self.reset_joints(
            self.body, links, targetValues=[[_PARKED], [0.0]], targetVelocities=[[0.0], [0.0]]
        )
        self.motors(
            self.body,
            links,
            pybullet.POSITION_CONTROL,
            targetPositions=[0.0, 0.0],
            forces=[0.0, 0.0],
        )
        self.placed.discard(name)

    def place(self, names: Sequence[str], pos: Sequence[float], vel: Sequence[float]) -> None:
        """Stand rods ``names`` in the table at joint values ``pos`` and speeds ``vel`` (each
        rod's slide, then its spin)."""
        links = [link for name in names for link in self.links[name]]
        if links:
            self.reset_joints(
                self.body,
                links,
                targetValues=[[v] for v in pos],
                targetVelocities=[[v] for v in vel],
            )
            self.placed.update(names)

    def clamp(self, links: Sequence[int], speeds: Sequence[float]) -> None:
        """Give these links' motors their top speed back where a velocity command took it."""
        for link, speed in zip(links, speeds):
            if link in self.unclamped:
                self.client.setJointMotorControl2(
                    self.body, link, pybullet.POSITION_CONTROL, force=0.0, maxVelocity=speed
                )
                self.unclamped.discard(link)

    def set_step(self, dt: float, substeps: int = 1) -> None:
        """Make a step of the world ``dt`` seconds long, taken in ``substeps`` equal physics
        steps within the one call (the same physics, one call to Bullet instead of several)."""
        if (dt, substeps) != (self.dt, self.substeps):
            erp = ERP_RATE * dt / substeps
            self.set_engine(
                fixedTimeStep=dt,
                numSubSteps=substeps if substeps > 1 else 0,
                erp=erp,
                contactERP=erp,
            )
            self.dt, self.substeps = dt, substeps

    def clear(self, base_dt: float) -> None:
        """Step once with the ball alone, high above the table: Bullet forgets what it carries
        in the ball from step to step (cached contacts, solver impulses), so a state plays out
        the same in this world whatever it held before (without it, a hair of 1e-34 apart)."""
        self.reset_pose(self.ball, _ASIDE, UPRIGHT)
        self.reset_velocity(self.ball, _STILL, _STILL)
        self.set_step(base_dt)
        self.step()

    def ball_state(self) -> tuple:
        """The ball's position, orientation, velocity and spin."""
        position, orientation = self.pose(self.ball)
        velocity, spin = self.velocity(self.ball)
        return position, orientation, velocity, spin

    def put_ball(self, state: tuple) -> None:
        position, orientation, velocity, spin = state
        self.reset_pose(self.ball, position, orientation)
        self.reset_velocity(self.ball, velocity, spin)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.disconnect()
