"""How the safety layer lets a joint's targets move: inside its limits, no faster than its
drive.

The real table's safety layer (:mod:`foosball_gym.real_table.hardware.safety`) sends every target
through a :class:`TargetLimiter`; the environments' ``safety_layer`` option sends their actions
through the same one (:mod:`foosball_gym.envs.safety_layer`), so here, where both sides may reach
it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from foosball_gym import table

# A margin that keeps a rod's targets off its end stops (m for slides, rad for spins), where a
# table's configuration sets none.
DEFAULT_LIMIT_MARGIN = {"slide": 0.005, "spin": 0.1}


@dataclass(frozen=True)
class JointLimits:
    """What a joint's targets must respect: ``[lower, upper]``, speed and acceleration."""

    lower: float
    upper: float
    max_speed: float
    max_acceleration: float

    @classmethod
    def of(cls, joint: Any) -> JointLimits:
        """The limits of a configured joint (a
        :class:`~foosball_gym.real_table.hardware.config.JointConfig`): the table's limit minus the
        joint's margin."""
        # JointConfig fills in the defaults of those left None.
        assert joint.limit_margin is not None and joint.max_speed is not None
        assert joint.max_acceleration is not None
        reach = joint.hard_limit - joint.limit_margin
        return cls(-reach, reach, joint.max_speed, joint.max_acceleration)

    @classmethod
    def simulated(cls, rod: str, kind: str) -> JointLimits:
        """The limits of a joint of the simulated table (``foosball play --table sim``): the
        default margin, the drive's top speed, and the acceleration the simulated drive
        reaches."""
        reach = (table.rod(rod).slide_limit if kind == "slide" else table.SPIN_LIMIT) - (
            DEFAULT_LIMIT_MARGIN[kind]
        )
        top = table.SLIDE_MAX_SPEED if kind == "slide" else table.SPIN_MAX_SPEED
        return cls(-reach, reach, top, table.drive_acceleration(table.rod(rod), kind))


class TargetLimiter:
    """Shapes one joint's targets, one control period at a time.

    The output moves towards the requested target (clamped into the limits) as fast as speed
    and acceleration allow, and slows down in time to stop at the target or at a limit without
    braking harder than ``max_acceleration``. A joint that starts outside its limits (a rod
    parked against an end stop) is brought back in at the same rates, never moved further out.

    Args:
        limits: the joint's limits.
        dt: the control period in seconds.
        position: where the joint is now.
    """

    def __init__(self, limits: JointLimits, dt: float, position: float = 0.0) -> None:
        if dt <= 0:
            raise ValueError(f"the control period must be positive, got {dt}")
        self.limits = limits
        self.dt = dt
        self.reset(position)

    def reset(self, position: float) -> None:
        """Start from a joint at rest at ``position`` (what the drive reports)."""
        self.position = float(position)
        self.velocity = 0.0
        self.goal = min(max(self.position, self.limits.lower), self.limits.upper)

    def _stopping_speed(self, distance: float) -> float:
        """The fastest speed from which the joint stops within ``distance``.

        Discrete, as the targets are: braking from ``v`` moves the joint ``v * dt``, then
        ``(v - u) * dt``, ... with ``u = a * dt``, down to a step below ``u``. From
        ``v = n * u`` that covers ``u * dt * n * (n + 1) / 2``; between two such speeds the
        distance grows linearly, with ``n + 1`` steps.
        """
        if distance <= 0.0:
            return 0.0
        u, dt = self.limits.max_acceleration * self.dt, self.dt
        n = math.floor((math.sqrt(1.0 + 8.0 * distance / (u * dt)) - 1.0) / 2.0)
        return (distance / dt + u * n * (n + 1) / 2.0) / (n + 1)

    def step(self, target: float | None = None) -> float:
        """The next target to send.

        Args:
            target: what the caller asks for; ``None`` keeps going to the last one.

        Raises:
            ValueError: for a target that is not a finite number.
        """
        lim = self.limits
        if target is not None:
            if not math.isfinite(target):
                raise ValueError(f"target must be a finite number, got {target!r}")
            self.goal = min(max(target, lim.lower), lim.upper)
        p, v, dt = self.position, self.velocity, self.dt
        error = self.goal - p
        wanted = math.copysign(self._stopping_speed(abs(error)), error)
        dv = lim.max_acceleration * dt
        v_new = min(max(wanted, v - dv, -lim.max_speed), v + dv, lim.max_speed)
        # Keep the ability to stop before either limit (v_new only shrinks here).
        v_new = min(v_new, self._stopping_speed(lim.upper - p))
        v_new = max(v_new, -self._stopping_speed(p - lim.lower))
        p_new = p + v_new * dt
        # Rounding must never carry a target over a limit; a joint already outside only moves in.
        p_new = min(max(p_new, min(lim.lower, p)), max(lim.upper, p))
        self.velocity = (p_new - p) / dt
        self.position = p_new
        return p_new
