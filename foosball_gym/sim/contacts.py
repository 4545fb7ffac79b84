"""Where the ball and the figurines can get to within a step: what decides which rods the
simulator hands to Bullet and how finely it steps.

Before each step the simulator bounds where the ball (by its speed) and each figurine (by what
its drive asks for) can get to. Where the ball could touch a figurine, a wall or the surface from
above within the step, the step is split into physics steps fine enough that nothing moves more
than ``contact_travel`` relative to what it may touch (twice that near a wall alone, which is
flat). The rods that could touch the ball are the ones Bullet must simulate; the others cannot
meet it and move by their drives alone (:mod:`foosball_gym.sim.drives`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

from foosball_gym import table

if TYPE_CHECKING:
    from foosball_gym.sim.drives import RodDrives

# Where a figurine can be, in the plane across its rod (distances from the rod's axis): the
# body, a box round the axis, reaches BODY_REACH; the leg spans LEG_INNER..LEG_OUTER (the
# reach of the sole) within LEG_HALF_ANGLE either side of the line the spin angle points along.
BODY_REACH = math.hypot(table.ROD_HEIGHT - table.FIGURINE_LEG_TOP, table.FIGURINE_SIZE[0] / 2)
LEG_INNER = table.ROD_HEIGHT - table.FIGURINE_LEG_TOP
LEG_OUTER = table.FIGURINE_REACH
LEG_HALF_ANGLE = math.atan2(
    max(max(-x0, x1) for _, x0, x1 in table.FIGURINE_LEG_SECTIONS), LEG_INNER
)
FIGURINE_HALF_WIDTH = table.FIGURINE_SIZE[1] / 2
# What a check of "could these touch within the step" adds to the distances, for the rounding
# of everything it leaves out (the ball's spin, contact slop).
NEAR_MARGIN = 0.002
# Near a wall alone, physics steps may be this many times the contact travel: rebounds keep
# 0.48-0.51 of the normal speed even at 20 mm per step.
WALL_TRAVEL_FACTOR = 2.0
# A ball falling faster than this (m/s) can bounce on the surface; slower, it rolls or rests.
FALLING = 0.3


def angle_between(a: float, b: float) -> float:
    """|a - b| wrapped into [0, pi]."""
    d = (a - b) % (2 * math.pi)
    return 2 * math.pi - d if d > math.pi else d


def distance_to_leg_sweep(rho: float, phi: float, spin: float, sweep: float) -> float:
    """Distance from a point (polar: ``rho`` from the axis, at angle ``phi``) to everywhere a
    figurine's leg goes while its spin angle moves within ``spin`` +- ``sweep``."""
    half = sweep + LEG_HALF_ANGLE
    off = angle_between(phi, spin)
    if off <= half or half >= math.pi:
        return max(0.0, rho - LEG_OUTER, LEG_INNER - rho)
    # Outside the swept sector: the nearest point is on one of its two edges.
    a = off - half
    along, across = rho * math.cos(a), rho * math.sin(a)
    if along < LEG_INNER:
        return math.hypot(LEG_INNER - along, across)
    if along > LEG_OUTER:
        return math.hypot(along - LEG_OUTER, across)
    return rho * math.sin(a)


class Reach:
    """The near-contact test for one table.

    Args:
        rods: the rods in play, in the order of ``drives``' joints.
        drives: their drives (positions, speeds, targets).
        accel: per joint, the most its drive changes its speed per second.
        physics_hz: the base physics rate.
        contact_travel: the most anything may move relative to what it may touch in one
            physics step near a contact (m).
    """

    def __init__(
        self,
        rods: Sequence[table.Rod],
        drives: RodDrives,
        accel: Sequence[float],
        physics_hz: int,
        contact_travel: float,
    ) -> None:
        self.rods = tuple(rods)
        self.drives = drives
        self.accel = list(accel)
        self.physics_hz = physics_hz
        self.contact_travel = contact_travel
        self._n = len(self.rods)
        self._xs = [(i, rod.x) for i, rod in enumerate(self.rods)]

    def plan(
        self, ball: Sequence[float], dt: float, candidates: Sequence[int] | None = None
    ) -> tuple[int, tuple[int, ...]]:
        """Physics steps for the next ``dt`` seconds, and the rods whose figurines the ball may
        meet within them (indices into ``rods``, in order; of ``candidates`` only, where
        given: the rods a plan for a longer step around this one found).

        One step per base step unless the ball could touch a wall or a figurine; else enough
        that nothing it could touch moves more than ``contact_travel`` relative to it per step.
        A ball a figurine may kick can leave at (1 + restitution) times the foot's speed on top
        of its own, and then meet other rods within the same step: they are counted in too.
        """
        least = max(1, round(dt * self.physics_hz))
        x, y, z, vx, vy, vz = ball
        speed = math.sqrt(vx * vx + vy * vy + vz * vz)
        wall_gap = min(table.FIELD_HALF_WIDTH - abs(y), table.FIELD_HALF_LENGTH - abs(x))
        touching: list[int] = []
        figurine = 0.0
        reach = speed * dt + NEAR_MARGIN + table.BALL_RADIUS
        while True:
            # A figurine reaches no further than LEG_OUTER from its axis: rods further off in
            # x are out of it at once.
            limit = LEG_OUTER + reach
            found = False
            for i, rod_x in self._xs if candidates is None else [self._xs[i] for i in candidates]:
                if -limit < x - rod_x < limit and i not in touching:
                    foot = self._touch_speed(i, x, y, z, reach, dt)
                    if foot is not None:
                        touching.append(i)
                        figurine = max(figurine, foot)
                        found = True
            if not found:
                break
            # A kick: the ball may leave faster than it came, and reach further rods.
            fastest = min(
                speed + (1 + table.BALL_FIGURINE_RESTITUTION) * figurine, table.RESOLVED_SPEED
            )
            further = fastest * dt + NEAR_MARGIN + table.BALL_RADIUS
            if further <= reach:
                break
            reach = further
        reach = speed * dt + NEAR_MARGIN + table.BALL_RADIUS
        wall = wall_gap < reach or (vz < -FALLING and z < reach)
        if not touching:
            if not wall:
                return least, ()
            # A wall is flat: how deep the ball gets in before it bounces does not turn the
            # bounce, so walls alone need only half the resolution of a figurine's round end.
            travel = WALL_TRAVEL_FACTOR * self.contact_travel
            return max(least, math.ceil(min(speed, table.RESOLVED_SPEED) * dt / travel)), ()
        # Faster than the spec's fastest ball only a foot swinging at full speed goes; it is
        # resolved as coarsely as a 20 m/s ball, so a step's travel grows with its speed.
        relative = min(
            speed + (1 + table.BALL_FIGURINE_RESTITUTION) * figurine, table.RESOLVED_SPEED
        )
        return max(least, math.ceil(relative * dt / self.contact_travel)), tuple(sorted(touching))

    def _touch_speed(
        self, i: int, x: float, y: float, z: float, reach: float, dt: float
    ) -> float | None:
        """How fast rod ``i``'s figurines may move at the ball within ``dt``, or None if none of
        them can come within ``reach`` of its centre."""
        rod = self.rods[i]
        dx = x - rod.x
        dz = z - table.ROD_HEIGHT
        rho = math.sqrt(dx * dx + dz * dz)
        if rho - reach > LEG_OUTER:
            return None  # beyond the reach of the rod's figurines at any spin
        drives, n = self.drives, self._n
        v = drives.speed_bound(i, dt, self.accel[i])
        w = drives.speed_bound(n + i, dt, self.accel[n + i])
        if rho - reach >= BODY_REACH:
            phi = math.atan2(rod.direction * dx, -dz)
            if distance_to_leg_sweep(rho, phi, drives.pos[n + i], w * dt) >= reach:
                return None
        gap = reach + v * dt + FIGURINE_HALF_WIDTH
        slide, d = drives.pos[i], rod.direction
        if any(abs(d * (slide + off) - y) < gap for off in rod.figurine_offsets):
            return v + w * LEG_OUTER
        return None
