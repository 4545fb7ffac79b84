"""Bullet worlds for the simulated table: the only code that imports pybullet.

A :class:`World` is one ``BulletClient`` holding the table (surface, walls, goals), some of the
rods and a ball. A table keeps a world with no rods, where the ball rolls while no figurine can
reach it, and a world for each pair of neighbouring rods, used while the ball is near them
(:class:`TableWorlds`). A world costs 28 MB and 12 ms to start (its client's buffers), which is
why rods share worlds by pairs instead of each set of rods having one.

Worlds are not shared between tables: Bullet keeps the ball's contacts from step to step to
start its solver from, and a world set up afresh every control step for whichever table used it
last loses them, and a ball pinned under a foot jitters.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from functools import cache
from typing import TYPE_CHECKING

from foosball_gym import table
from foosball_gym.sim.urdf import urdf_file, urdf_path, urdf_with_rods

if TYPE_CHECKING:
    from foosball_gym.sim.drives import RodDrives


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


# How fast (1/s) Bullet pushes penetrating bodies apart. The velocity it adds also adds to a
# bounce, and for contacts with a multibody (the table, a figurine) it cannot be split off:
# Bullet's 0.2 per step made a wall rebound keep 0.51-0.70 of the normal speed instead of 0.5;
# 0.01 per 240 Hz step keeps 0.48-0.51, and a ball at rest still sits on the surface to 0.01 mm.
# Per second, so that finer steps do not push harder.
ERP_RATE = 0.01 * table.PHYSICS_HZ
# Where a world's ball waits while Bullet forgets its contacts (see World.clear).
_ASIDE = (0.0, 0.0, 5.0)
_STILL = (0.0, 0.0, 0.0)
UPRIGHT = (0.0, 0.0, 0.0, 1.0)
# Rods closer than this (m) share a world: the ball can be near both within a base step.
_WINDOW_SPAN = 2 * (table.FIGURINE_REACH + table.BALL_RADIUS) + 0.2
# Where a world's rod that is not simulated waits (a slide, m): its figurines far beside the
# table, out of the ball's way, at rest.
_PARKED = 10.0


def connect(gui: bool = False, options: str = "") -> BulletClient:
    """A new Bullet world; ``options`` are the GUI window's (``--width=960 ...``)."""
    with _quiet_stdout():
        return BulletClient(pybullet.GUI if gui else pybullet.DIRECT, options=options)


def _order(names: Sequence[str]) -> tuple[str, ...]:
    """Rod names in the table's order (``table.RODS``), as a world is keyed."""
    rank = {rod.name: k for k, rod in enumerate(table.RODS)}
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
        with urdf_file(urdf_with_rods(names)) as path, _quiet_stdout():
            body = client.loadURDF(path, useFixedBase=True)
        index = {
            client.getJointInfo(body, i)[1].decode(): i for i in range(client.getNumJoints(body))
        }
        slides, spins, gravity = [], [], []
        for name in names:
            rod = table.rod(name)
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

    ``urdf`` is the text of another URDF of the same table and rods (the GUI window's: see
    :func:`~foosball_gym.sim.urdf.urdf_for_window`); ``window_options`` size the GUI window.

    Which of its rods stand in the table (``placed``; the others wait parked, out of the ball's
    way) and what their motors were told (``sent``) is for the simulator to set.
    """

    def __init__(
        self,
        names: Sequence[str],
        *,
        gui: bool = False,
        urdf: str | None = None,
        window_options: str = "",
    ) -> None:
        self.names = _order(names)
        self.client = connect(gui, window_options)
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
        self.dt, self.substeps = 1.0 / table.PHYSICS_HZ, 1
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
        text = urdf or urdf_with_rods(self.names)
        with urdf_file(text) as path, _quiet_stdout():
            self.body = p.loadURDF(path, useFixedBase=True)
        index = {
            p.getJointInfo(self.body, i)[1].decode(): i for i in range(p.getNumJoints(self.body))
        }
        # Each rod's slide and spin link.
        self.links = {
            name: (index[table.rod(name).slide_joint], index[table.rod(name).spin_joint])
            for name in self.names
        }
        p.changeDynamics(self.body, -1, maxJointVelocity=table.SPIN_MAX_SPEED * 1.1)
        self.clamps: dict[int, float | None] = {}
        for slide, spin in self.links.values():
            for link, force, speed in (
                (slide, table.SLIDE_MAX_FORCE, table.SLIDE_MAX_SPEED),
                (spin, table.SPIN_MAX_TORQUE, table.SPIN_MAX_SPEED),
            ):
                p.changeDynamics(
                    self.body, link, linearDamping=0.0, angularDamping=0.0, jointDamping=0.0
                )
                # The speed clamp set here (``clamps``) stays with Bullet's motor; position
                # commands keep it, a velocity command drops it (None)
                p.setJointMotorControl2(
                    self.body,
                    link,
                    pybullet.POSITION_CONTROL,
                    targetPosition=0.0,
                    force=force,
                    maxVelocity=speed,
                )
                self.clamps[link] = speed
        with _quiet_stdout():
            self.ball = p.loadURDF(
                str(urdf_path("ball.urdf")),
                [0.0, 0.0, table.BALL_RADIUS],
                useMaximalCoordinates=True,
            )
        self.placed: set[str] = set(self.names)
        for name in self.names:
            self.park(name)
        # What the placed rods' motors were last told (see TableSim._send), and by whom.
        self.sent: tuple | None = None
        self.mode = "position"
        # The ball's and the materials' dynamics last applied (see set_materials).
        self.dynamics: tuple | None = None

    def set_materials(
        self,
        *,
        mass: float,
        friction: float,
        restitution: float,
        damping: float,
        rolling_resistance: float,
    ) -> None:
        """Give the ball and the surfaces it touches these materials (see
        ``TableSim.set_ball_dynamics``); nothing to do where they are already."""
        values = (mass, friction, restitution, damping, rolling_resistance)
        if self.dynamics == values:
            return
        self.dynamics = values
        p = self.client
        table_friction = table.combine(friction, table.TABLE_MATERIAL.dynamic_friction)
        # Bullet keeps one friction and one restitution per body and multiplies two bodies'
        # values; the authors' engine averages them. The ball is the only body that touches
        # anything, so it carries 1 and each body it can touch carries the value of its
        # contact with the ball (table.py: BALL_TABLE_*, BALL_FIGURINE_*). The ball on a
        # figurine departs from the authors' average (table.py says why); a randomised ball
        # friction scales it in proportion.
        figurine_friction = (
            table.BALL_FIGURINE_FRICTION * friction / table.BALL_MATERIAL.dynamic_friction
        )
        p.changeDynamics(
            self.body,
            -1,
            lateralFriction=table_friction,
            restitution=table.TABLE_MATERIAL.restitution,
        )
        for _, link in self.links.values():
            p.changeDynamics(
                self.body,
                link,
                lateralFriction=figurine_friction,
                restitution=table.FIGURINE_MATERIAL.restitution,
            )
        # A rolling resistance torque mu * N slows a rolling solid sphere by (5/7) g mu / r;
        # Bullet's torque coefficient for the ball on the table is the ball's rolling friction
        # times the table's friction.
        rolling = 1.4 * rolling_resistance * table.BALL_RADIUS / table_friction
        p.changeDynamics(
            self.ball,
            -1,
            mass=mass,
            lateralFriction=1.0,
            restitution=restitution / table.TABLE_MATERIAL.restitution,
            rollingFriction=rolling,
            linearDamping=damping,
            angularDamping=0.0,
            ccdSweptSphereRadius=0.0,
        )

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

    def drive_to(
        self,
        links: Sequence[int],
        targets: Sequence[float],
        forces: Sequence[float],
        gains: Sequence[float],
        speeds: Sequence[float],
    ) -> None:
        """Position motors: each link asks for ``gain * error`` (per physics step) within its
        top speed, with at most its force."""
        self._clamp(links, speeds)
        self.motors(
            self.body,
            links,
            pybullet.POSITION_CONTROL,
            targetPositions=targets,
            forces=forces,
            positionGains=gains,
        )

    def drive_at(
        self, links: Sequence[int], speeds: Sequence[float], forces: Sequence[float]
    ) -> None:
        """Velocity motors (the targets within the drives' top speed: Bullet drops the clamp)."""
        self.motors(
            self.body, links, pybullet.VELOCITY_CONTROL, targetVelocities=speeds, forces=forces
        )
        self.clamps.update(dict.fromkeys(links))

    def let_go(self, links: Sequence[int]) -> None:
        """Motors without force, so that raw torques can move the joints (a position motor
        without force sets no constraint and keeps its speed clamp)."""
        zeros = [0.0] * len(links)
        self.motors(
            self.body, links, pybullet.POSITION_CONTROL, targetPositions=zeros, forces=zeros
        )

    def push(self, links: Sequence[int], torques: Sequence[float]) -> None:
        """Apply forces or torques to the joints for the next physics step."""
        self.motors(self.body, links, pybullet.TORQUE_CONTROL, forces=torques)

    def _clamp(self, links: Sequence[int], speeds: Sequence[float]) -> None:
        """Give these links' motors their top speed, where a velocity command took it or the
        drive's top speed changed."""
        for link, speed in zip(links, speeds):
            if self.clamps[link] != speed:
                self.client.setJointMotorControl2(
                    self.body, link, pybullet.POSITION_CONTROL, force=0.0, maxVelocity=speed
                )
                self.clamps[link] = speed

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

    def save(self) -> bytes:
        """Everything Bullet holds of this world (the bodies' state and the contacts it carries
        from step to step) as the bytes of a ``.bullet`` file, for :meth:`load`."""
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "world.bullet")
            self.client.saveBullet(path)
            with open(path, "rb") as file:
                return file.read()

    def load(self, saved: bytes, dt: float, substeps: int) -> None:
        """Put this world in the state :meth:`save` took from a world of the same rods, whose
        step was ``dt`` in ``substeps``. Bullet saves no motors: the next step tells them."""
        with tempfile.TemporaryDirectory() as folder:
            path = os.path.join(folder, "world.bullet")
            with open(path, "wb") as file:
                file.write(saved)
            try:
                self.client.restoreState(fileName=path)
            except pybullet.error as err:
                msg = f"a saved Bullet world does not fit this one (rods {self.names})"
                raise ValueError(msg + ": saved from other rods or by another Bullet") from err
        # Loading brings the saved world's solver settings; the step is set to match them.
        self.dt = math.nan
        self.set_step(dt, substeps)
        self.sent = None

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.disconnect()


class TableWorlds:
    """The worlds of one table, and the one that holds the ball.

    A world of its own with no rods, where the ball rolls while no figurine can reach it, and
    one for each pair of neighbouring rods (a rod too far from any other for the ball to be
    near both has one of its own), made with the table; a set of rods no pair holds (three, for
    a kicked ball that may reach both neighbours of a rod) gets a world of its own when first
    needed. Entering a world carries the ball and the simulated rods over from the drives and
    the world left.

    Args:
        rods: the rods in play, in the order of ``drives``' joints.
        drives: their drives.
        physics_hz: the base physics rate.

    Attributes:
        own: the world without rods.
        current: the world that holds the ball.
        simulated: the rods (indices) standing in ``current``; ``joints`` their drive joints
            (slides, then spins), ``links`` their links there, ``parked`` the other joints.
    """

    def __init__(self, rods: Sequence[table.Rod], drives: RodDrives, physics_hz: int) -> None:
        self.rods = tuple(rods)
        self._drives = drives
        self._base_dt = 1.0 / physics_hz
        self._n = n = len(self.rods)
        by_x = sorted(range(n), key=lambda i: self.rods[i].x)
        self._windows = [
            tuple(sorted(pair))
            for pair in zip(by_x, by_x[1:])
            if abs(self.rods[pair[0]].x - self.rods[pair[1]].x) <= _WINDOW_SPAN
        ]
        self._windows += [(i,) for i in range(n) if not any(i in w for w in self._windows)]
        self.own = self.current = World(())
        self._worlds: dict[tuple[str, ...], World] = {}
        # Made now, not as the ball first comes near: each takes 16 ms to make, more than a
        # table that keeps real time can spare within a control step.
        for window in self._windows:
            self._world_of(window)
        self.simulated: tuple[int, ...] = ()
        self.joints: list[int] = []
        self.links: list[int] = []
        self.parked: list[int] = list(range(2 * n))

    def holds(self, world: World, rods: Sequence[int]) -> bool:
        return all(self.rods[i].name in world.links for i in rods)

    def use(
        self, rods: tuple[int, ...], ball: Callable[[], tuple], materials: dict[str, float]
    ) -> World:
        """The world to simulate exactly ``rods`` (indices) in, set up and made current;
        ``ball`` gives the ball's state to carry over, should the world change."""
        world = self.current
        if not rods:
            if world is not self.own:
                self.enter(self.own, (), ball(), materials)
            return self.own
        if world is self.own or not self.holds(world, rods):
            world = self._world_of(self._window(rods))
            self.enter(world, rods, ball(), materials)
        elif rods != self.simulated:
            self._arrange(world, rods, everything=False)
        return world

    def enter(
        self, world: World, rods: tuple[int, ...], ball: tuple, materials: dict[str, float]
    ) -> None:
        """Make ``world`` current: cleared, holding the ball in state ``ball`` and ``rods`` as
        the drives have them."""
        world.set_materials(**materials)
        world.clear(self._base_dt)
        self.current = world
        self._arrange(world, rods, everything=True)
        world.put_ball(ball)

    def take_rods(self) -> None:
        """Copy the simulated rods' joint values and speeds from Bullet into the drives."""
        if self.joints:
            drives, world = self._drives, self.current
            for j, state in zip(self.joints, world.joint_states(world.body, self.links)):
                drives.pos[j], drives.vel[j] = state[0], state[1]

    def send(self, dt: float) -> None:
        """Tell the simulated rods' motors what the drives ask for, at a physics step of
        ``dt``."""
        drives, world = self._drives, self.current
        mode = drives.mode
        # Bullet turns a motor's force into the most impulse it may give in one step of the
        # step size at the time of the command: a command is sent again whenever that changes.
        # (A velocity command sent once at 240 Hz gave a drive eleven times its torque in the
        # fine steps near a contact.)
        key = (drives.version, dt if mode != "torque" else 0.0)
        if world.sent == key:
            return
        world.sent = key
        joints, links = self.joints, self.links
        forces = [drives.max_force[j] for j in joints]
        if mode == "position":
            # Bullet's position gain is per physics step: the speed it asks for is
            # gain * error / dt.
            world.drive_to(
                links,
                [drives.targets[j] for j in joints],
                forces,
                [drives.gains[j] * dt for j in joints],
                [drives.max_speed[j] for j in joints],
            )
        elif mode == "velocity":
            world.drive_at(links, [drives.velocity_targets[j] for j in joints], forces)
        else:
            # Bullet's joint motors must let go before raw torques can move the joints.
            world.let_go(links)

    def save(self) -> tuple:
        """What :meth:`load` needs to carry on as these worlds would: the rods (indices) of the
        world holding the ball (none: the world without rods), those standing in it, the world
        saved whole and its step ``(dt, substeps)``. Entering any other world clears it."""
        world = self.current
        window = tuple(i for i, rod in enumerate(self.rods) if rod.name in world.links)
        return window, self.simulated, world.save(), (world.dt, world.substeps)

    def load(self, saved: tuple, ball: tuple, materials: dict[str, float]) -> None:
        """Carry on from what :meth:`save` gave on a table of the same rods, the drives already
        in their saved state; ``ball`` is the ball's state then."""
        window, simulated, bullet, step = saved
        world = self._world_of(window) if window else self.own
        self.enter(world, simulated, ball, materials)
        world.load(bullet, *step)

    def close(self) -> None:
        for world in (self.own, *self._worlds.values()):
            world.close()

    def _window(self, rods: Sequence[int]) -> tuple[int, ...]:
        """The rods of the world to simulate ``rods`` in: the first of the windows that holds
        them all, or else all rods in play between them."""
        for window in self._windows:
            if all(i in window for i in rods):
                return window
        low = min(self.rods[i].x for i in rods)
        high = max(self.rods[i].x for i in rods)
        return tuple(i for i in range(self._n) if low <= self.rods[i].x <= high)

    def _world_of(self, rods: tuple[int, ...]) -> World:
        names = tuple(self.rods[i].name for i in rods)
        world = self._worlds.get(names)
        if world is None:
            world = self._worlds[names] = World(names)
        return world

    def _arrange(self, world: World, rods: tuple[int, ...], everything: bool) -> None:
        """Stand ``rods`` in ``world`` from the drives' state (all of them with
        ``everything``, else those not standing yet) and park its others."""
        names = {self.rods[i].name for i in rods}
        for name in list(world.placed):
            if name not in names:
                world.park(name)
        joining = [i for i in rods if everything or self.rods[i].name not in world.placed]
        n, drives = self._n, self._drives
        joints = [j for i in joining for j in (i, n + i)]
        world.place(
            [self.rods[i].name for i in joining],
            [drives.pos[j] for j in joints],
            [drives.vel[j] for j in joints],
        )
        self.simulated = rods
        self.joints = [*rods, *(n + i for i in rods)]
        self.links = [world.links[self.rods[i].name][0] for i in rods] + [
            world.links[self.rods[i].name][1] for i in rods
        ]
        self.parked = [j for j in range(2 * n) if j not in self.joints]
        world.sent = None
