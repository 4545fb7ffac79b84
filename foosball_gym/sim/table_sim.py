"""The simulated table: the rods' drives, the ball and goals, over Bullet worlds
(:mod:`foosball_gym.sim.worlds`).

A :class:`TableSim` advances the table in control steps. Goals and a ball leaving the table are
checked after every physics step where the ball could reach a goal line or fly that high, so a
fast ball cannot cross the goal line and bounce back out unseen.

Most of a step's cost in Bullet is the rods, and a rod the ball cannot reach needs none of it.
So the rods are moved by their drives' own law (:mod:`foosball_gym.sim.drives`, step for step
what Bullet's motors do), and Bullet holds the table and the ball alone, until some figurine
could meet the ball (:mod:`foosball_gym.sim.contacts`): those rods are then handed to a Bullet
world that holds them, for as long as they could.

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

import contextlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.camera import CameraModel
from foosball_gym.sim.contacts import Reach
from foosball_gym.sim.drives import CONTROL_MODES, RodDrives, drive_acceleration
from foosball_gym.sim.dynamics import draw_dynamics
from foosball_gym.sim.options import check_physics
from foosball_gym.sim.view import View, check_image_size
from foosball_gym.sim.worlds import ERP_RATE, UPRIGHT, TableWorlds, World, drive_masses

__all__ = [
    "AWAY_SCORED",
    "CONTROL_MODES",
    "HOME_SCORED",
    "NO_GOAL",
    "BallState",
    "TableSim",
    "inside_walls",
]

NO_GOAL, HOME_SCORED, AWAY_SCORED = table.NO_GOAL, table.HOME_SCORED, table.AWAY_SCORED
# The drives' position gains (1/s): a 0.1 m slide target reached in about 90 ms without overshoot.
SLIDE_GAIN = 48.0
SPIN_GAIN = 72.0


def drive_limits(rods: Sequence[table.Rod]) -> dict[str, list[float]]:
    """What :class:`RodDrives` takes for these rods' joints besides their gains: every rod's
    slide, then every rod's spin."""
    n = len(rods)
    mass, gravity = drive_masses(tuple(r.name for r in rods))
    return {
        "mass": list(mass),
        "gravity": list(gravity),
        "max_force": [table.SLIDE_MAX_FORCE] * n + [table.SPIN_MAX_TORQUE] * n,
        "max_speed": [table.SLIDE_MAX_SPEED] * n + [table.SPIN_MAX_SPEED] * n,
        "lower": [-r.slide_limit for r in rods] + [-table.SPIN_LIMIT] * n,
        "upper": [r.slide_limit for r in rods] + [table.SPIN_LIMIT] * n,
    }


@dataclass
class BallState:
    position: np.ndarray  # (3,) metres
    velocity: np.ndarray  # (3,) m/s


# How deep (m) the ball's centre may be in a wall, the surface or a pocket's wall before it
# counts as gone through: half the thinnest of them, where Bullet pushes it out on the far
# side. A ball that bounces stays a radius off, short of its surface.
_THROUGH = table.WALL_THICKNESS / 2


def inside_walls(x: float, y: float, z: float) -> bool:
    """Whether the ball's centre ``(x, y, z)`` is within the table: over the field below
    OUT_OF_TABLE_HEIGHT, or in a goal mouth or its pocket."""
    ax, ay = abs(x), abs(y)
    if z < -_THROUGH or z > table.OUT_OF_TABLE_HEIGHT:
        return False
    if ax <= table.FIELD_HALF_LENGTH + _THROUGH and ay <= table.FIELD_HALF_WIDTH + _THROUGH:
        return True
    return (
        ax <= table.POCKET_BACK_X + _THROUGH
        and ay <= table.GOAL_HALF_WIDTH + _THROUGH
        and z <= table.GOAL_HEIGHT + _THROUGH
    )


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
        physics_hz: int = table.PHYSICS_HZ,
        control_hz: int = table.CONTROL_HZ,
        contact_travel: float = table.CONTACT_TRAVEL,
        rolling_resistance: float = table.ROLLING_RESISTANCE,
        gui: bool = False,
        slide_gain: float = SLIDE_GAIN,
        spin_gain: float = SPIN_GAIN,
    ) -> None:
        physics_hz, control_hz, contact_travel, rolling_resistance = check_physics(
            physics_hz, control_hz, contact_travel, rolling_resistance
        )
        names = tuple(rods)
        for name in names:
            table.rod(name)
        if len(set(names)) != len(names):
            raise ValueError(f"each rod may be in play once, got {names}")
        self.rods: tuple[table.Rod, ...] = tuple(table.rod(n) for n in names)
        self.physics_hz = physics_hz
        self.control_hz = control_hz
        self.substeps = physics_hz // control_hz
        self.control_dt = 1.0 / control_hz
        self.contact_travel = contact_travel
        self.gui = gui
        self._closed = True
        # The GUI's window first: without a display it fails before anything is built.
        self._view: View | None = View(self.rods, gui=True) if gui else None
        self._n = n = len(self.rods)
        self._drives = RodDrives(**drive_limits(self.rods), gains=[0.0] * 2 * n, erp_rate=ERP_RATE)
        # How fast the drives may change their rods' speed, for the near-contact test: the
        # figure of the rods' own inertia, twelve times what Bullet (which takes a rod's
        # inertia from its collision shapes' bounding box) lets them. Held to the drives' real
        # acceleration, the test took fewer fine steps and scripted full games lost 30 balls
        # off the table in 200 instead of 9.
        accel = [drive_acceleration(r, "slide") for r in self.rods] + [
            drive_acceleration(r, "spin") for r in self.rods
        ]
        self._accel = accel
        self._reach = Reach(self.rods, self._drives, accel, physics_hz, contact_travel)
        self.set_drive_gains(slide_gain, spin_gain)

        self.ball_mass = table.BALL_MASS
        self.ball_friction = table.BALL_MATERIAL.dynamic_friction
        self.ball_restitution = table.BALL_TABLE_RESTITUTION
        self.ball_damping = table.BALL_LINEAR_DAMPING
        self.rolling_resistance = rolling_resistance
        self._worlds = TableWorlds(self.rods, self._drives, physics_hz)
        self._closed = False
        self._worlds.own.set_materials(**self._materials())
        # The ball's position, orientation, velocity and spin as the last step left it (None
        # while a world holding it has moved on).
        self._ball_state: tuple | None = (
            (0.0, 0.0, table.BALL_RADIUS),
            UPRIGHT,
            (0.0,) * 3,
            (0.0,) * 3,
        )
        self._worlds.own.put_ball(self._ball_state)
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

    def draw_dynamics(
        self,
        ranges: dict[str, tuple[float, float]],
        rng: np.random.Generator,
        base_gains: tuple[float, float],
        joints: Sequence[tuple[str, str]] | None = None,
    ) -> dict[str, float]:
        """Draw and set the physical parameters the domain randomisation ``ranges`` give; see
        :func:`foosball_gym.sim.dynamics.draw_dynamics`."""
        return draw_dynamics(self, ranges, rng, base_gains, joints)

    def set_drive_limits(self, speed: Sequence[float], accel: Sequence[float]) -> None:
        """Scale each drive's top speed and most acceleration (its force or torque) by these
        factors, one per joint in play (slides, then spins); 1 is the table's own drive."""
        sizes = {len(speed), len(accel)}
        if sizes != {2 * self._n} or not all(0 < float(f) < math.inf for f in (*speed, *accel)):
            raise ValueError(f"drive limits take {2 * self._n} speed and accel factors, each > 0")
        nominal = drive_limits(self.rods)
        self._drives.set_limits(
            [s * f for s, f in zip(nominal["max_speed"], speed)],
            [m * f for m, f in zip(nominal["max_force"], accel)],
        )
        # The near-contact test's bound, set for the rated drives, grows with a stronger one;
        # a weaker one keeps it, and the fine steps near a contact stay as fine.
        self._reach.accel = [a * max(1.0, f) for a, f in zip(self._accel, accel)]

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
        self._worlds.current.set_materials(**self._materials())

    def _materials(self) -> dict[str, float]:
        """The ball's and the surfaces' materials, as a world takes them."""
        return {
            "mass": self.ball_mass,
            "friction": self.ball_friction,
            "restitution": self.ball_restitution,
            "damping": self.ball_damping,
            "rolling_resistance": self.rolling_resistance,
        }

    @property
    def _world(self) -> World:
        return self._worlds.current

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
        slides = np.zeros(self._n) if slide is None else np.asarray(slide, dtype=float)
        spins = np.zeros(self._n) if spin is None else np.asarray(spin, dtype=float)
        if slides.shape != (self._n,) or spins.shape != (self._n,):
            raise ValueError(f"slide and spin need one value per rod in play ({self._n})")
        ball = self._ball_from(ball_position, ball_velocity, rolling=False)
        drives = self._drives
        drives.pos[:] = [float(v) for v in (*slides, *spins)]
        drives.vel[:] = [0.0] * (2 * self._n)
        self._ball_state = ball
        self._worlds.enter(self._worlds.own, (), ball, self._materials())
        self.command("position", list(drives.pos))
        if self._view is not None:
            self._sync_view()

    def place_ball(
        self,
        position: Sequence[float],
        velocity: Sequence[float] = (0.0, 0.0),
        *,
        rolling: bool = False,
        spin: Sequence[float] | None = None,
    ) -> None:
        """Put the ball somewhere, leaving the rods as they are (a serve in a running game).

        Args:
            position: (x, y) on the surface, or (x, y, z).
            velocity: (vx, vy) or (vx, vy, vz). The ball starts without spin, sliding, as a
                shot leaves a foot: the table's friction makes it roll within a few metres. (A
                ball given the spin of rolling at 15 m/s climbs a wall it meets: friction on
                its spinning face threw it 0.26 m up.)
            rolling: start with the spin of rolling without slipping instead.
            spin: start with this angular velocity (rad/s about x, y, z) instead.
        """
        ball = self._ball_from(position, velocity, rolling=rolling)
        if spin is not None:
            omega = tuple(float(w) for w in spin)
            if len(omega) != 3 or not all(math.isfinite(w) for w in omega):
                raise ValueError(f"ball spin takes 3 finite values (rad/s), got {spin!r}")
            ball = (*ball[:3], omega)
        self._put_ball(ball)

    @staticmethod
    def _ball_from(position: Sequence[float], velocity: Sequence[float], rolling: bool) -> tuple:
        pos = [float(v) for v in position]
        vel = [float(v) for v in velocity]
        if len(pos) == 2:
            pos.append(table.BALL_RADIUS)
        if len(vel) == 2:
            vel.append(0.0)
        if len(pos) != 3 or len(vel) != 3:
            raise ValueError("ball position and velocity take 2 (x, y) or 3 (x, y, z) values")
        spin = rolling_spin(vel[0], vel[1]) if rolling else (0.0,) * 3
        return tuple(pos), UPRIGHT, tuple(vel), tuple(spin)

    def _put_ball(self, ball: tuple) -> None:
        """Put the ball into this table's own world (entering it, if another was in use)."""
        self._ball_state = ball
        worlds = self._worlds
        if worlds.current is worlds.own:
            worlds.own.put_ball(ball)
        else:
            worlds.enter(worlds.own, (), ball, self._materials())
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
            :data:`NO_GOAL`. Stepping stops at the physics step where either event happens. A
            ball found outside the walls at the end of the step (see :func:`inside_walls`) is
            out of the table too.
        """
        drives, substeps, n, worlds = self._drives, self.substeps, self._n, self._worlds
        steps, touching = self._reach.plan(self._ball(), self.control_dt)
        base = 1.0 / self.physics_hz
        if not touching or steps <= 2 * substeps:
            world = worlds.use(touching, self._ball_full, self._materials())
            result, taken = self._advance(world, self.control_dt, steps, watch=bool(touching))
            worlds.take_rods()
            # The others go as far as the ball did, to the base step.
            drives.advance(worlds.parked, base, -(-taken * substeps // steps))
        else:
            result, taken = (NO_GOAL, False), 0
            while taken < substeps and result == (NO_GOAL, False):
                steps, meeting = self._reach.plan(self._ball(), base, touching)
                if worlds.current is not worlds.own and worlds.holds(worlds.current, meeting):
                    # A rod that met the ball earlier in this control step stays in Bullet.
                    keep = [i for i in worlds.simulated if i in touching and i not in meeting]
                    meeting = tuple(sorted((*meeting, *keep)))
                world = worlds.use(meeting, self._ball_full, self._materials())
                result, _ = self._advance(world, base, steps, watch=True)
                worlds.take_rods()
                # The rods that may meet the ball later in this control step keep pace with it.
                waiting = [i for i in touching if i not in meeting]
                if waiting:
                    drives.advance([*waiting, *(n + i for i in waiting)], base)
                taken += 1
            # The rods that cannot meet the ball within the control step, all at once.
            far = [i for i in range(n) if i not in touching]
            drives.advance([*far, *(n + i for i in far)], base, taken)
        self._ball_state = self._world.ball_state()
        if result == (NO_GOAL, False) and not inside_walls(*self._ball()[:3]):
            result = (NO_GOAL, True)  # through a wall: too fast a ball, a kick into a post
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
        drives, worlds = self._drives, self._worlds
        torques = None
        if worlds.joints:
            world.set_step(dt)  # before the motors are told: Bullet sizes their impulse by it
            worlds.send(dt)
            if drives.mode == "torque":
                torques = [drives.torques[j] for j in worlds.joints]
        step, box, ball = world.step, world.box, world.ball
        line, half = table.GOAL_LINE_X, table.GOAL_HALF_WIDTH
        if not watch:
            # Without a figurine to kick it, the ball goes no faster than it does now; twice
            # as far, for a spinning ball that a wall turns upwards.
            x, _, z, vx, vy, vz = self._ball()
            travel = 2 * math.sqrt(vx * vx + vy * vy + vz * vz) * duration
            watch = abs(x) + travel >= line or z + travel >= table.OUT_OF_TABLE_HEIGHT
        self._ball_state = None
        self.physics_steps += steps
        if not watch and torques is None:
            if world is worlds.own and steps == self.substeps:
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
                world.push(worlds.links, torques)
            step()
            # Twice the centre: the sum of the ball's bounding box's corners.
            (x, y, z), (x1, y1, z1) = box(ball)
            x, y, z = x + x1, y + y1, z + z1
            if (x > 2 * line or x < -2 * line) and -2 * half <= y <= 2 * half:
                return ((HOME_SCORED if x > 0 else AWAY_SCORED), False), k + 1
            if z > 2 * table.OUT_OF_TABLE_HEIGHT:
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
        return self._posed_view().world

    def _posed_view(self) -> View:
        if self._view is None:
            self._view = View(self.rods, gui=False)
        self._sync_view()
        return self._view

    def _sync_view(self) -> None:
        assert self._view is not None
        x, y, z, _, _, _ = self._ball()
        self._view.pose(self._drives.pos, self._drives.vel, (x, y, z))

    def figurine_positions(self) -> np.ndarray:
        """World centres of every figurine on the rods in play, (N, 3), rod by rod."""
        pos = self._drives.pos
        return figurine_centres(self.rods, pos[: self._n], pos[self._n :])

    # ----------------------------------------------------------------------------- output

    def show_text(self, lines: Sequence[str]) -> None:
        """Write ``lines`` in the GUI window, the first above the table and the others below
        it, replacing what the last call wrote; without the GUI, nothing."""
        if self.gui:
            self._posed_view().show_text(lines)

    def set_view(self, view: str) -> None:
        """Look at the table in the GUI window from ``view``: ``"top"``, ``"away"`` or
        ``"home"`` (see :data:`~foosball_gym.sim.view.VIEWS`); without the GUI, nothing."""
        if self.gui:
            self._posed_view().set_view(view)

    def keyboard_events(self) -> tuple[frozenset[str], frozenset[str]]:
        """The keys held down in the GUI window now, and those pressed since the last call
        (see :meth:`View.keyboard_events`); without the GUI there are no keys."""
        if not self.gui:
            return frozenset(), frozenset()
        return self._posed_view().keyboard_events()

    def camera(self, width: int, height: int) -> CameraModel:
        """The model of the camera :meth:`render` draws through at this size."""
        return self._posed_view().camera(width, height)

    def render(
        self,
        width: int = 320,
        height: int = 180,
        layered: bool = True,
        scene: tuple[Sequence[float], Sequence[float]] | None = None,
    ) -> np.ndarray:
        """An (height, width, 3) uint8 top view from the CPU renderer (see
        :meth:`View.render`), of the table as it stands or of ``scene`` (as :meth:`scene`
        gives it)."""
        check_image_size(width, height)  # before a view is built for it
        view = self._posed_view()
        if scene is not None:
            positions, ball = scene
            view.pose(positions, [0.0] * len(positions), ball)
        return view.render(width, height, layered)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._worlds.close()
            if self._view is not None:
                self._view.close()

    # ----------------------------------------------------------------------------- copies

    def __getstate__(self) -> dict[str, Any]:
        """A copy (pickle, deepcopy) is a table of its own in the same state: the drives, the
        ball and the Bullet world that holds it, saved whole so that the copy steps as this
        table would, bit for bit. A closed table copies as a closed one."""
        if self.gui:
            raise TypeError(
                "a simulated table with the PyBullet GUI open (render_mode='human') cannot be "
                "copied: PyBullet opens one GUI window per process. Copy one made with "
                "render_mode=None or 'rgb_array'"
            )
        state = {k: v for k, v in self.__dict__.items() if k not in ("_worlds", "_view")}
        state["_view"] = None  # drawn afresh by the copy, when it is first drawn
        if not self._closed:
            state["_ball_state"] = self._ball_full()
            state["_worlds"] = self._worlds.save()
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        saved = state.pop("_worlds", None)
        self.__dict__.update(state)
        if saved is not None:
            self._worlds = TableWorlds(self.rods, self._drives, self.physics_hz)
            self._worlds.load(saved, state["_ball_state"], self._materials())

    def __del__(self) -> None:
        with contextlib.suppress(Exception):
            self.close()


def rolling_spin(vx: float, vy: float) -> tuple[float, float, float]:
    """The angular velocity (rad/s) of a ball rolling on the table at (vx, vy) m/s without
    slipping."""
    return -vy / table.BALL_RADIUS, vx / table.BALL_RADIUS, 0.0


def figurine_centres(
    rods: Sequence[table.Rod], slide: Sequence[float], spin: Sequence[float]
) -> np.ndarray:
    """World centres of the figurines of ``rods`` for given joint values, (N, 3)."""
    out = []
    for rod, s, a in zip(rods, slide, spin):
        x, z = rod.figurine_swing(a)
        out += [(x, y, z) for y in rod.figurine_y(s)]
    return np.array(out, dtype=float).reshape(-1, 3)
