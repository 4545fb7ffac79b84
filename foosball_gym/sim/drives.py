"""The rods' drives as plain arithmetic: how Bullet's joint motors move a rod the ball is not
touching.

Bullet spends most of a step on the rods: each joint motor is a constraint row that costs a
pass over the whole articulation, and a rod far from the ball needs none of it. Such a rod is
moved here instead, by the law Bullet's motor applies to a joint of its own (each rod's slide and
spin are independent degrees of freedom: the slide runs along the spin axis), step for step:

1. the joint's speed grows by gravity's pull on the rod's centre of mass (spin only: the
   figurines hang below the axis);
2. the motor asks for a speed (position control: ``gain * (target - position)``; velocity
   control: the target) within the drive's top speed, and gets it as far as an impulse of
   ``max_force * dt`` can take the joint's mass or inertia (torque control: the torque
   accelerates it instead);
3. a joint at or beyond its end stop is held there, pushed back by Bullet's penetration
   recovery where it is in by less than 0.04 (Bullet's split-impulse threshold);
4. the position moves by the new speed times the step.

Measured against Bullet over 300 control steps of random targets on four rods in each control
mode, end stops included, each control step started from Bullet's state: positions agree to
2e-7 (1e-16 away from the stops, where Bullet's iterative solver leaves 1e-5 rad/s behind;
``tests/test_rod_drives.py``). So a rod moves the same whether the simulator hands it to Bullet
(the ball is near) or keeps it here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

# Re-exported: the simulator's drives are the table's (foosball_gym.table computes the limit).
from foosball_gym.table import drive_acceleration as drive_acceleration

CONTROL_MODES = ("position", "velocity", "torque")
# Bullet moves a joint that is this far beyond its end stop back without its penetration
# recovery (split impulse): deeper, it is only stopped.
_SPLIT_DEPTH = 0.04


class RodDrives:
    """The drive state of every joint in play: slides first, then spins, rod by rod.

    Args:
        mass: per joint, what the drive moves: the slide's mass (kg) or the spin's moment of
            inertia about its axis (kg m^2), as Bullet holds them.
        gravity: per joint, gravity's torque on the spin at a quarter turn (N m; 0 for
            slides): the joint accelerates by ``-gravity * sin(angle) / mass``.
        max_force, max_speed: the drive's limits per joint (N or N m; m/s or rad/s).
        lower, upper: the end stops per joint.
        gains: position gains per joint (1/s).
        erp_rate: Bullet's penetration recovery rate at the end stops (1/s).
    """

    def __init__(
        self,
        *,
        mass: Sequence[float],
        gravity: Sequence[float],
        max_force: Sequence[float],
        max_speed: Sequence[float],
        lower: Sequence[float],
        upper: Sequence[float],
        gains: Sequence[float],
        erp_rate: float,
    ) -> None:
        self.n = len(mass)
        for name, values in (
            ("gravity", gravity),
            ("max_force", max_force),
            ("max_speed", max_speed),
            ("lower", lower),
            ("upper", upper),
            ("gains", gains),
        ):
            if len(values) != self.n:
                raise ValueError(f"{name} needs one value per joint ({self.n})")
        self.mass = [float(m) for m in mass]
        self._pull = [-float(g) / m for g, m in zip(gravity, self.mass)]
        self.max_force = [float(f) for f in max_force]
        self.max_speed = [float(s) for s in max_speed]
        self.lower = [float(v) for v in lower]
        self.upper = [float(v) for v in upper]
        self.gains = [float(g) for g in gains]
        self.erp_rate = float(erp_rate)
        self._tabulate()
        self.pos = [0.0] * self.n
        self.vel = [0.0] * self.n
        self.mode = "position"
        self.targets = [0.0] * self.n
        self.velocity_targets = [0.0] * self.n
        self.torques = [0.0] * self.n
        # Raised by every change a motor in Bullet must be told of (targets, mode, gains).
        self.version = 0

    def _tabulate(self) -> None:
        # Per joint: gravity's pull (per sin of the angle), the end stops, the top speed and
        # the drive's most acceleration.
        self._joint = [
            (pull, lo, hi, top, force / m)
            for pull, lo, hi, top, force, m in zip(
                self._pull, self.lower, self.upper, self.max_speed, self.max_force, self.mass
            )
        ]

    def set_gains(self, gains: Sequence[float]) -> None:
        self.gains = [float(g) for g in gains]
        self.version += 1

    def set_limits(self, max_speed: Sequence[float], max_force: Sequence[float]) -> None:
        """New top speeds and forces (or torques) per joint, for the next command and step."""
        if len(max_speed) != self.n or len(max_force) != self.n:
            raise ValueError(f"max_speed and max_force need one value per joint ({self.n})")
        self.max_speed = [float(s) for s in max_speed]
        self.max_force = [float(f) for f in max_force]
        self._tabulate()
        # The standing commands, held to the new limits as a command is.
        self.velocity_targets = [
            max(-m, min(m, t)) for t, m in zip(self.velocity_targets, self.max_speed)
        ]
        self.torques = [max(-m, min(m, t)) for t, m in zip(self.torques, self.max_force)]
        self.version += 1

    def command(self, mode: str, targets: Sequence[float]) -> None:
        """Targets for every joint, clamped to what the drive can do (see ``TableSim.command``)."""
        if mode not in CONTROL_MODES:
            raise ValueError(f"unknown control mode {mode!r}; allowed: {', '.join(CONTROL_MODES)}")
        if len(targets) != self.n:
            raise ValueError(f"need {self.n} targets (slides, then spins), got {len(targets)}")
        if mode == "position":
            self.targets = [
                lo if t < lo else hi if t > hi else float(t)
                for t, lo, hi in zip(targets, self.lower, self.upper)
            ]
        elif mode == "velocity":
            self.velocity_targets = [
                -m if t < -m else m if t > m else float(t) for t, m in zip(targets, self.max_speed)
            ]
        else:
            self.torques = [
                -m if t < -m else m if t > m else float(t) for t, m in zip(targets, self.max_force)
            ]
        self.mode = mode
        self.version += 1

    def advance(self, joints: Iterable[int], dt: float, steps: int = 1) -> None:
        """Move ``joints`` through ``steps`` physics steps of ``dt`` seconds each."""
        pos, vel, mode = self.pos, self.vel, self.mode
        for j in joints:
            q, v = pos[j], vel[j]
            pull, lo, hi, top, accel = self._joint[j]
            pull *= dt
            most = accel * dt  # the most speed one step can add
            if mode == "position":
                gain, target = self.gains[j], self.targets[j]
                for _ in range(steps):
                    if pull:
                        v += pull * math.sin(q)
                    asked = gain * (target - q)
                    if asked > top:
                        asked = top
                    elif asked < -top:
                        asked = -top
                    if asked - v > most:
                        v += most
                    elif asked - v < -most:
                        v -= most
                    else:
                        v = asked
                    if q <= lo or q >= hi:
                        v = self._held(q, v, lo, hi)
                    q += v * dt
            else:
                asked = self.velocity_targets[j]
                push = self.torques[j] / self.mass[j] * dt
                for _ in range(steps):
                    if pull:
                        v += pull * math.sin(q)
                    if mode == "torque":
                        v += push
                    elif asked - v > most:
                        v += most
                    elif asked - v < -most:
                        v -= most
                    else:
                        v = asked
                    if q <= lo or q >= hi:
                        v = self._held(q, v, lo, hi)
                    q += v * dt
            pos[j], vel[j] = q, v

    def _held(self, q: float, v: float, lo: float, hi: float) -> float:
        """The speed an end stop leaves a joint at or beyond it: at most the penetration
        recovery's push back, none where it is in deeper than the split-impulse threshold."""
        if q <= lo:
            depth = lo - q
            least = depth * self.erp_rate if depth < _SPLIT_DEPTH else 0.0
            return least if v < least else v
        depth = q - hi
        most = -depth * self.erp_rate if depth < _SPLIT_DEPTH else 0.0
        return most if v > most else v

    def speed_bound(self, j: int, dt: float, accel: float) -> float:
        """The fastest joint ``j`` can move within the next ``dt`` seconds, its drive able to
        change its speed by at most ``accel`` per second.

        A position drive asks for gain * error (clamped to its top speed) and gets there from
        the speed it has, so its speed stays between the two; a velocity drive likewise with
        its target. Under torque control only the drive's top speed bounds it. The slack covers
        a drive overshooting the speed it asks for; not always a ball knocking a rod about
        (scripted full games: in 1.3 % of control steps a knocked rod went faster, up to 3.8
        times), but such a rod is at the ball already, in Bullet, in fine steps.
        """
        now = abs(self.vel[j])
        top = self.max_speed[j]
        if self.mode == "position":
            asked = self.gains[j] * abs(self.targets[j] - self.pos[j])
        elif self.mode == "velocity":
            asked = abs(self.velocity_targets[j])
        else:
            asked = top
        reachable = now + accel * dt
        return min(top, 1.2 * max(now, min(asked, reachable)) + 0.02 * top)
