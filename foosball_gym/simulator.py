"""The simulated table: the rods' drives, the ball, goals and the view, over Bullet worlds
(:mod:`foosball_gym.bullet_worlds`; with it, the only module that imports pybullet).

A :class:`TableSim` advances the table in control steps. Goals and a ball leaving the table are
checked after every physics step where the ball could reach a goal line or fly that high, so a
fast ball cannot cross the goal line and bounce back out unseen.

Most of a step's cost in Bullet is the rods, and a rod the ball cannot reach needs none of it.
So the rods are moved by their drives' own law (:mod:`foosball_gym.rod_drives`, step for step
what Bullet's motors do), and Bullet holds the table and the ball alone, until some figurine
could meet the ball (:mod:`foosball_gym.reach`): those rods are then handed to a Bullet world
that holds them, for as long as they could.

How contacts stay right at every speed (measured; see ``benchmarks/physics_report.py``):

- Bullet's continuous collision detection would stop tunnelling, but its predictive contacts
  carry no restitution, so a fast ball died against a wall. The ball has none here. Instead,
  where the ball could touch a figurine, a wall or the surface from above within the step,
  the step is split into physics steps fine enough that nothing moves more than
  ``contact_travel`` relative to what it may touch (twice that near a wall alone, which is
  flat); while a figurine may meet a fast ball this is decided again every base step. Far
  from everything the table runs at ``physics_hz``.
- Bullet pushes penetrating bodies apart with a velocity (ERP) that adds to a bounce; with
  multibody contacts it cannot be split off, so its gain is kept near zero.
- A position gain in Bullet acts per physics step; the drives' gains here are per second and
  rescaled to whatever step is taken, so a drive behaves the same at every step size.

Rods that are not in play are left out of the model: they cannot touch the ball and cost
nothing to simulate.
"""

from __future__ import annotations

import collections
import contextlib
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from foosball_gym import table as T
from foosball_gym.bullet_worlds import ERP_RATE, UPRIGHT, World, drive_masses, pybullet
from foosball_gym.camera import CameraModel
from foosball_gym.physics_options import check_physics
from foosball_gym.reach import Reach
from foosball_gym.rod_drives import CONTROL_MODES, RodDrives

__all__ = ["AWAY_SCORED", "CONTROL_MODES", "HOME_SCORED", "NO_GOAL", "BallState", "TableSim"]

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
# Rods closer than this (m) share a world: the ball can be near both within a base step.
_WINDOW_SPAN = 2 * (T.FIGURINE_REACH + T.BALL_RADIUS) + 0.2


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
        self._view: World | None = None
        # The worlds of pairs of neighbouring rods (and, made as the ball first needs them,
        # of more rods: three, for a kicked ball that may reach both neighbours).
        self._worlds: dict[tuple[str, ...], World] = {}
        if gui and sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
            raise RuntimeError(
                "the PyBullet GUI (render_mode='human') needs a display and "
                "DISPLAY is not set; on a headless machine use "
                "render_mode='rgb_array', or run under xvfb-run"
            )
        self._n = n = len(self.rods)
        mass, gravity = drive_masses(names)
        self._drives = RodDrives(
            mass=mass,
            gravity=gravity,
            max_force=[T.SLIDE_MAX_FORCE] * n + [T.SPIN_MAX_TORQUE] * n,
            max_speed=[T.SLIDE_MAX_SPEED] * n + [T.SPIN_MAX_SPEED] * n,
            lower=[-r.slide_limit for r in self.rods] + [-T.SPIN_LIMIT] * n,
            upper=[r.slide_limit for r in self.rods] + [T.SPIN_LIMIT] * n,
            gains=[0.0] * 2 * n,
            erp_rate=ERP_RATE,
        )
        # How fast the drives may change their rods' speed, for the near-contact test: the
        # figure of the rods' own inertia, twelve times what Bullet (which takes a rod's
        # inertia from its collision shapes' bounding box) lets them. Held to the drives' real
        # acceleration, the test took fewer fine steps and scripted full games lost 30 balls
        # off the table in 200 instead of 9.
        accel = [drive_acceleration(r, "slide") for r in self.rods] + [
            drive_acceleration(r, "spin") for r in self.rods
        ]
        self._reach = Reach(self.rods, self._drives, accel, physics_hz, contact_travel)
        # Rods the ball may meet are simulated in the world of a pair of neighbouring rods
        # (a rod too far from any other for the ball to be near both has one of its own).
        by_x = sorted(range(n), key=lambda i: self.rods[i].x)
        self._windows = [
            tuple(sorted(pair))
            for pair in zip(by_x, by_x[1:])
            if abs(self.rods[pair[0]].x - self.rods[pair[1]].x) <= _WINDOW_SPAN
        ]
        self._windows += [(i,) for i in range(n) if not any(i in w for w in self._windows)]
        self.set_drive_gains(slide_gain, spin_gain)

        self.ball_mass = T.BALL_MASS
        self.ball_friction = T.BALL_MATERIAL.dynamic_friction
        self.ball_restitution = T.BALL_TABLE_RESTITUTION
        self.ball_damping = T.BALL_LINEAR_DAMPING
        self.rolling_resistance = rolling_resistance
        self._text_items: list[tuple[str, int]] = []
        self._keyboard_taken = False
        self._closed = False
        if gui:
            self._view = self._view_of_all(gui=True)
        # The table and the ball alone: this table's own world.
        self._own = self._world = World(())
        self._apply_dynamics(self._own)
        # Made now, not as the ball first comes near: each takes 16 ms to make, more than a
        # table that keeps real time can spare within a control step.
        for window in self._windows:
            self._world_of(tuple(self.rods[i].name for i in window))
        # The ball's position, orientation, velocity and spin as the last step left it (None
        # while a world holding it has moved on).
        self._ball_state: tuple | None = (
            (0.0, 0.0, T.BALL_RADIUS),
            UPRIGHT,
            (0.0,) * 3,
            (0.0,) * 3,
        )
        self._own.put_ball(self._ball_state)
        # The rods simulated in the world in use, their drive joints (slides, then spins) and
        # links there, and the drive joints that are not.
        self._simulated: tuple[int, ...] = ()
        self._joints: list[int] = []
        self._links: list[int] = []
        self._parked: list[int] = list(range(2 * n))
        self._camera: CameraModel | None = None
        self._view_matrix = self._proj = None
        self._shapes: list[tuple[int, int, int, list[float]]] | None = None
        self._fixed_shown = True
        self._fixed_layers: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self.physics_steps = 0

    # ----------------------------------------------------------------------------- set-up

    @property
    def slide_gain(self) -> float:
        return self._gains[0]

    @property
    def spin_gain(self) -> float:
        return self._gains[1]

    def set_drive_gains(self, slide_gain: float, spin_gain: float) -> None:
        """Position gains of the simulated drives in 1/s (used in position mode)."""
        if not (slide_gain > 0 and spin_gain > 0) or not math.isfinite(slide_gain + spin_gain):
            raise ValueError(f"drive gains must be positive, got {slide_gain}, {spin_gain}")
        self._gains = (float(slide_gain), float(spin_gain))
        self._drives.set_gains([self._gains[0]] * self._n + [self._gains[1]] * self._n)

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
        if self._world is self._own:
            self._apply_dynamics(self._own)

    def _apply_dynamics(self, world: World) -> None:
        """Give the ball and the surfaces it touches this table's materials in ``world``."""
        values = (
            self.ball_mass,
            self.ball_friction,
            self.ball_restitution,
            self.ball_damping,
            self.rolling_resistance,
        )
        if world.dynamics == values:
            return
        world.dynamics = values
        p = world.client
        table_friction = T.combine(self.ball_friction, T.TABLE_MATERIAL.dynamic_friction)
        # Bullet keeps one friction and one restitution per body and multiplies two bodies'
        # values; the authors' engine averages them. The ball is the only body that touches
        # anything, so it carries 1 and each body it can touch carries the value of its
        # contact with the ball (table.py: BALL_TABLE_*, BALL_FIGURINE_*). The ball on a
        # figurine departs from the authors' average (table.py says why); a randomised ball
        # friction scales it in proportion.
        figurine_friction = (
            T.BALL_FIGURINE_FRICTION * self.ball_friction / T.BALL_MATERIAL.dynamic_friction
        )
        p.changeDynamics(
            world.body, -1, lateralFriction=table_friction, restitution=T.TABLE_MATERIAL.restitution
        )
        for _, link in world.links.values():
            p.changeDynamics(
                world.body,
                link,
                lateralFriction=figurine_friction,
                restitution=T.FIGURINE_MATERIAL.restitution,
            )
        # A rolling resistance torque mu * N slows a rolling solid sphere by (5/7) g mu / r;
        # Bullet's torque coefficient for the ball on the table is the ball's rolling friction
        # times the table's friction.
        rolling = 1.4 * self.rolling_resistance * T.BALL_RADIUS / table_friction
        p.changeDynamics(
            world.ball,
            -1,
            mass=self.ball_mass,
            lateralFriction=1.0,
            restitution=self.ball_restitution / T.TABLE_MATERIAL.restitution,
            rollingFriction=rolling,
            linearDamping=self.ball_damping,
            angularDamping=0.0,
            ccdSweptSphereRadius=0.0,
        )

    # ----------------------------------------------------------------------------- worlds

    def _window(self, rods: Sequence[int]) -> tuple[int, ...]:
        """The rods of the world to simulate ``rods`` in: the first of the table's windows
        that holds them all, or else all rods in play between them."""
        for window in self._windows:
            if all(i in window for i in rods):
                return window
        low = min(self.rods[i].x for i in rods)
        high = max(self.rods[i].x for i in rods)
        return tuple(i for i in range(self._n) if low <= self.rods[i].x <= high)

    def _holds(self, world: World, rods: Sequence[int]) -> bool:
        return all(self.rods[i].name in world.links for i in rods)

    def _simulate(self, rods: tuple[int, ...]) -> World:
        """Set up a world to simulate exactly ``rods`` (indices), and use it."""
        world = self._world
        if not rods:
            if world is not self._own:
                self._enter(self._own, ())
            return self._own
        if world is self._own or not self._holds(world, rods):
            world = self._world_of(tuple(self.rods[i].name for i in self._window(rods)))
            self._enter(world, rods)
        elif rods != self._simulated:
            self._arrange(world, rods, everything=False)
        return world

    def _world_of(self, names: tuple[str, ...]) -> World:
        world = self._worlds.get(names)
        if world is None:
            world = self._worlds[names] = World(names)
        return world

    def _enter(self, world: World, rods: tuple[int, ...]) -> None:
        """Use ``world`` from now on: cleared, holding the ball as it is and ``rods`` as the
        drives have them."""
        ball = self._ball_full()
        self._apply_dynamics(world)
        world.clear(1.0 / self.physics_hz)
        self._world = world
        self._arrange(world, rods, everything=True)
        world.put_ball(ball)
        self._ball_state = ball

    def _arrange(self, world: World, rods: tuple[int, ...], everything: bool) -> None:
        """Stand ``rods`` in ``world`` from the drives' state (all of them with
        ``everything``, else those not standing yet) and park its others."""
        names = {self.rods[i].name: i for i in rods}
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
        self._simulated = rods
        self._joints = [*rods, *(n + i for i in rods)]
        self._links = [world.links[self.rods[i].name][0] for i in rods] + [
            world.links[self.rods[i].name][1] for i in rods
        ]
        self._parked = [j for j in range(2 * n) if j not in self._joints]
        world.sent = None

    def _take_rods(self) -> None:
        """Copy the simulated rods' joint values and speeds from Bullet into the drives."""
        if self._joints:
            drives, world = self._drives, self._world
            for j, state in zip(self._joints, world.joint_states(world.body, self._links)):
                drives.pos[j], drives.vel[j] = state[0], state[1]

    def _send(self, world: World, dt: float) -> None:
        """Tell the simulated rods' motors what the drives ask for, at a physics step of
        ``dt``."""
        drives = self._drives
        mode = drives.mode
        # Bullet turns a motor's force into the most impulse it may give in one step of the
        # step size at the time of the command: a command is sent again whenever that changes.
        # (A velocity command sent once at 240 Hz gave a drive eleven times its torque in the
        # fine steps near a contact.)
        key = (drives.version, dt if mode != "torque" else 0.0)
        if world.sent == key:
            return
        world.sent = key
        joints, links = self._joints, self._links
        forces = [drives.max_force[j] for j in joints]
        if mode == "position":
            world.clamp(links, [drives.max_speed[j] for j in joints])
            # Bullet's position gain is per physics step: the speed it asks for is
            # gain * error / dt.
            world.motors(
                world.body,
                links,
                pybullet.POSITION_CONTROL,
                targetPositions=[drives.targets[j] for j in joints],
                forces=forces,
                positionGains=[drives.gains[j] * dt for j in joints],
            )
        elif mode == "velocity":
            # The targets are within the drives' top speed; Bullet drops the clamp here.
            world.motors(
                world.body,
                links,
                pybullet.VELOCITY_CONTROL,
                targetVelocities=[drives.velocity_targets[j] for j in joints],
                forces=forces,
            )
            world.unclamped.update(links)
        else:
            # Bullet's joint motors must let go before raw torques can move the joints.
            world.motors(
                world.body,
                links,
                pybullet.POSITION_CONTROL,
                targetPositions=[0.0] * len(joints),
                forces=[0.0] * len(joints),
            )

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
        slide = np.zeros(self._n) if slide is None else np.asarray(slide, dtype=float)
        spin = np.zeros(self._n) if spin is None else np.asarray(spin, dtype=float)
        if slide.shape != (self._n,) or spin.shape != (self._n,):
            raise ValueError(f"slide and spin need one value per rod in play ({self._n})")
        ball = self._ball_from(ball_position, ball_velocity, rolling=False)
        drives = self._drives
        drives.pos[:] = [float(v) for v in (*slide, *spin)]
        drives.vel[:] = [0.0] * (2 * self._n)
        self._ball_state = ball
        self._enter(self._own, ())
        self.command("position", list(drives.pos))
        if self._view is not None:
            self._sync_view()

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
        self._put_ball(self._ball_from(position, velocity, rolling=rolling))

    @staticmethod
    def _ball_from(position: Sequence[float], velocity: Sequence[float], rolling: bool) -> tuple:
        pos = [float(v) for v in position]
        vel = [float(v) for v in velocity]
        if len(pos) == 2:
            pos.append(T.BALL_RADIUS)
        if len(vel) == 2:
            vel.append(0.0)
        if len(pos) != 3 or len(vel) != 3:
            raise ValueError("ball position and velocity take 2 (x, y) or 3 (x, y, z) values")
        spin = [-vel[1] / T.BALL_RADIUS, vel[0] / T.BALL_RADIUS, 0.0] if rolling else [0.0] * 3
        return tuple(pos), UPRIGHT, tuple(vel), tuple(spin)

    def _put_ball(self, ball: tuple) -> None:
        """Put the ball into this table's own world (entering it, if another was in use)."""
        self._ball_state = ball
        if self._world is self._own:
            self._own.put_ball(ball)
        else:
            self._enter(self._own, ())
        if self._view is not None:
            self._sync_view()

    def command(self, mode: str, targets: Sequence[float]) -> None:
        """Set the drives' targets for every joint in play.

        Args:
            mode: ``"position"`` (metres, radians; clamped to the joint limits),
                ``"velocity"`` (m/s, rad/s; clamped to the drives' speed) or ``"torque"``
                (N, N m; clamped to the drives' force and torque).
            targets: one per joint in play: every rod's slide, then every rod's spin.
        """
        self._drives.command(mode, targets)

    def step(self) -> tuple[int, bool]:
        """Advance one control step.

        Where the ball is far from every figurine, Bullet holds the table and the ball alone,
        and the rods move by their drives. Where a figurine may meet the ball, Bullet holds
        the rods that may meet it, in physics steps as fine as those contacts need; a fast
        contact is looked at again every base physics step, with the rods that may meet it
        then.

        Returns:
            ``(goal, out_of_table)``: goal is :data:`HOME_SCORED`, :data:`AWAY_SCORED` or
            :data:`NO_GOAL`. Stepping stops at the physics step where either event happens.
        """
        drives, substeps, n = self._drives, self.substeps, self._n
        steps, touching = self._reach.plan(self._ball(), self.control_dt)
        base = 1.0 / self.physics_hz
        if not touching or steps <= 2 * substeps:
            world = self._simulate(touching)
            result, taken = self._advance(world, self.control_dt, steps, watch=bool(touching))
            self._take_rods()
            # The others go as far as the ball did, to the base step.
            drives.advance(self._parked, base, -(-taken * substeps // steps))
        else:
            result, taken = (NO_GOAL, False), 0
            while taken < substeps and result == (NO_GOAL, False):
                steps, meeting = self._reach.plan(self._ball(), base, touching)
                if self._world is not self._own and self._holds(self._world, meeting):
                    # A rod that met the ball earlier in this control step stays in Bullet.
                    keep = [i for i in self._simulated if i in touching and i not in meeting]
                    meeting = tuple(sorted((*meeting, *keep)))
                world = self._simulate(meeting)
                result, _ = self._advance(world, base, steps, watch=True)
                self._take_rods()
                # The rods that may meet the ball later in this control step keep pace with it.
                waiting = [i for i in touching if i not in meeting]
                if waiting:
                    drives.advance([*waiting, *(n + i for i in waiting)], base)
                taken += 1
            # The rods that cannot meet the ball within the control step, all at once.
            far = [i for i in range(n) if i not in touching]
            drives.advance([*far, *(n + i for i in far)], base, taken)
        self._ball_state = self._world.ball_state()
        if self._view is not None:
            self._sync_view()
        return result

    def _advance(
        self, world: World, duration: float, steps: int, watch: bool
    ) -> tuple[tuple[int, bool], int]:
        """Step ``duration`` seconds in ``steps`` equal physics steps, watching for goals and
        a ball leaving the table after every one (with ``watch``, or where the ball could
        reach a goal line or fly that high within the steps).

        Returns:
            the outcome (see :meth:`step`) and the physics steps taken.
        """
        dt = duration / steps
        drives = self._drives
        torques = None
        if self._joints:
            world.set_step(dt)  # before the motors are told: Bullet sizes their impulse by it
            self._send(world, dt)
            if drives.mode == "torque":
                torques = [drives.torques[j] for j in self._joints]
        step, box, ball = world.step, world.box, world.ball
        line, half = T.GOAL_LINE_X, T.GOAL_HALF_WIDTH
        if not watch:
            # Without a figurine to kick it, the ball goes no faster than it does now; twice
            # as far, for a spinning ball that a wall turns upwards.
            x, _, z, vx, vy, vz = self._ball()
            travel = 2 * math.sqrt(vx * vx + vy * vy + vz * vz) * duration
            watch = abs(x) + travel >= line or z + travel >= T.OUT_OF_TABLE_HEIGHT
        self._ball_state = None
        self.physics_steps += steps
        if not watch and torques is None:
            if world is self._own and steps == self.substeps:
                world.set_step(duration, steps)  # the base steps of a control step, at once
                step()
            else:
                world.set_step(dt)
                for _ in range(steps):
                    step()
            return (NO_GOAL, False), steps
        world.set_step(dt)
        for k in range(steps):
            if torques is not None:
                world.motors(world.body, self._links, pybullet.TORQUE_CONTROL, forces=torques)
            step()
            # Twice the centre: the sum of the ball's bounding box's corners.
            (x, y, z), (x1, y1, z1) = box(ball)
            x, y, z = x + x1, y + y1, z + z1
            if (x > 2 * line or x < -2 * line) and -2 * half <= y <= 2 * half:
                return ((HOME_SCORED if x > 0 else AWAY_SCORED), False), k + 1
            if z > 2 * T.OUT_OF_TABLE_HEIGHT:
                return (NO_GOAL, True), k + 1
        return (NO_GOAL, False), steps

    def _ball_full(self) -> tuple:
        """The ball's position, orientation, velocity and spin now."""
        if self._ball_state is None:
            self._ball_state = self._world.ball_state()
        return self._ball_state

    def _ball(self) -> tuple[float, float, float, float, float, float]:
        (x, y, z), _, (vx, vy, vz), _ = self._ball_full()
        return x, y, z, vx, vy, vz

    def joint_states(self) -> tuple[list[float], list[float]]:
        """Positions and velocities of every joint in play: slides first, then spins."""
        return list(self._drives.pos), list(self._drives.vel)

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
        return list(self._drives.pos), [x, y, z]

    def show(self, positions: Sequence[float], ball: Sequence[float]) -> None:
        """Pose the rods and the ball as :meth:`scene` gave them, at rest, for rendering."""
        if len(positions) != 2 * self._n or len(ball) != 3:
            raise ValueError(f"show needs {2 * self._n} joint positions and the ball's x, y, z")
        drives = self._drives
        drives.pos[:] = [float(v) for v in positions]
        drives.vel[:] = [0.0] * (2 * self._n)
        _, orientation, velocity, spin = self._ball_full()
        self._put_ball((tuple(float(v) for v in ball), orientation, velocity, spin))

    def _view_world(self) -> World:
        """The whole table posed as things stand: what is drawn and shown in the GUI."""
        if self._view is None:
            self._view = self._view_of_all(gui=False)
        self._sync_view()
        return self._view

    def _view_of_all(self, gui: bool) -> World:
        return World([rod.name for rod in self.rods], gui=gui)

    def _sync_view(self) -> None:
        view = self._view
        assert view is not None
        view.place(
            [rod.name for rod in self.rods], *self._by_rod(self._drives.pos, self._drives.vel)
        )
        x, y, z, _, _, _ = self._ball()
        view.reset_pose(view.ball, (x, y, z), UPRIGHT)

    def _by_rod(
        self, pos: Sequence[float], vel: Sequence[float]
    ) -> tuple[list[float], list[float]]:
        """Joint values ordered rod by rod (each rod's slide, then its spin)."""
        n = self._n
        order = [j for i in range(n) for j in (i, n + i)]
        return [pos[j] for j in order], [vel[j] for j in order]

    # ----------------------------------------------------------------------------- the GUI

    def show_text(self, lines: Sequence[str]) -> None:
        """Write ``lines`` in the GUI window, the first above the table and the others below
        it, replacing what the last call wrote; without the GUI, nothing."""
        if not self.gui:
            return
        p = self._view_world().client
        lines = list(lines)
        for i, line in enumerate(lines):
            shown = self._text_items[i] if i < len(self._text_items) else None
            if shown is not None and shown[0] == line:
                continue
            beyond = T.FIELD_HALF_WIDTH + _TEXT_MARGIN
            y = beyond if i == 0 else -(beyond + (i - 1) * _TEXT_LINE)
            item = p.addUserDebugText(
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
            p.removeUserDebugItem(item)
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
        p = self._view_world().client
        if not self._keyboard_taken:
            p.configureDebugVisualizer(pybullet.COV_ENABLE_KEYBOARD_SHORTCUTS, 0)
            self._keyboard_taken = True
        held, pressed = set(), set()
        for code, state in p.getKeyboardEvents().items():
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
        pos = self._drives.pos
        return figurine_centres(self.rods, pos[: self._n], pos[self._n :])

    # ----------------------------------------------------------------------------- output

    def camera(self, width: int, height: int) -> CameraModel:
        if self._camera is None or (self._camera.width, self._camera.height) != (width, height):
            p = self._view_world().client
            cam = CameraModel(width, height)
            self._camera = cam
            self._view_matrix = p.computeViewMatrix(
                [0, 0, cam.height_above_table], [0, 0, 0], [0, 1, 0]
            )
            self._proj = p.computeProjectionMatrixFOV(
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
        self._view_world()
        self.camera(width, height)
        if not layered or self.gui:
            self._show_fixed_parts(True)
            return self._draw(width, height)[0]
        fixed_rgb, fixed_depth = self._fixed_layer(width, height)
        self._show_fixed_parts(False)
        rgb, depth = self._draw(width, height)
        return np.where((depth < fixed_depth)[:, :, None], rgb, fixed_rgb)

    def _draw(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        assert self._view is not None
        _, _, rgba, depth, _ = self._view.client.getCameraImage(
            width,
            height,
            self._view_matrix,
            self._proj,
            renderer=pybullet.ER_TINY_RENDERER,
            shadow=0,
            flags=pybullet.ER_NO_SEGMENTATION_MASK,
        )
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()
        return rgb, np.asarray(depth, dtype=np.float32).reshape(height, width)

    def _visual_shapes(self) -> list[tuple[int, int, int, list[float]]]:
        """(body, link, shape index, colour) of every visual shape, fixed parts first."""
        view = self._view
        assert view is not None
        if self._shapes is None:
            shapes, seen = [], collections.Counter()
            for body in (view.body, view.ball):
                for shape in view.client.getVisualShapeData(body):
                    link = shape[1]
                    shapes.append((body, link, seen[body, link], list(shape[7])))
                    seen[body, link] += 1
            self._shapes = shapes
        return self._shapes

    def _set_visible(self, fixed: bool, visible: bool) -> None:
        view = self._view
        assert view is not None
        for body, link, index, colour in self._visual_shapes():
            if (body == view.body and link == -1) == fixed:
                alpha = colour[3] if visible else 0.0
                view.client.changeVisualShape(
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
            for world in (self._own, self._view, *self._worlds.values()):
                if world is not None:
                    world.close()

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
