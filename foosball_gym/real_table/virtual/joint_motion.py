"""How a simulated drive moves its joint, one control step at a time: following its target,
braking on a ramp, holding under power, or coasting with its power stage off.

Positions are in drive increments, speeds in increments per second. The drive
(:class:`~foosball_gym.real_table.virtual.drive.SimulatedDrive`) decides when the motion changes
(its CiA 402 state and option codes); this says what the joint does meanwhile.
"""

from __future__ import annotations

import math

from foosball_gym.real_table.hardware.config import JointConfig
from foosball_gym.real_table.hardware.safety import TargetLimiter


class JointMotion:
    """The motion of one drive's joint.

    Args:
        joint: the joint (its calibration and end stops).
        dt: the control step (s), the period of the ramps.
        position: the joint's position at power-on (increments).

    Attributes:
        kind: ``"driven"`` (following the drive's target), ``"ramp"`` (braking), ``"hold"``
            (halted under power) or ``"free"`` (power stage off: coasting, or at rest).
        speed: the drive's own velocity in a ramp or while coasting.
        setpoint: where a ramp or coasting has the joint.
    """

    def __init__(self, joint: JointConfig, dt: float, position: int) -> None:
        self.joint = joint
        self.dt = dt
        self.kind = "free"
        self.speed = 0.0
        self.setpoint = float(position)
        self._deceleration = 0.0
        self._profile: TargetLimiter | None = None

    def moving_speed(self, velocity: int) -> float:
        """How fast the joint moves now: the motion's own speed in a ramp or coasting, the
        joint's last published ``velocity`` when driven, 0 when holding."""
        if self.kind == "driven":
            return abs(float(velocity))
        return abs(self.speed) if self.kind != "hold" else 0.0

    def follow(self, profile: TargetLimiter | None) -> None:
        """Power on: the joint follows the drive's target, through ``profile`` where given."""
        self._profile = profile
        self.kind = "driven"

    def brake(self, deceleration: float, position: int, velocity: int) -> bool:
        """Start braking at ``deceleration``, from the joint's published state if it was driven.

        Returns:
            True when there is no ramp to brake on (``deceleration`` 0): the joint halts on the
            spot, which the caller then declares with :meth:`halt`.
        """
        if self.kind == "driven":
            self.setpoint, self.speed = float(position), float(velocity)
        self._deceleration = abs(deceleration)
        self.kind = "ramp"
        return not self._deceleration

    def halt(self, hold: bool) -> None:
        """A ramp ended: the joint holds under power, or (``hold`` False) is free at rest."""
        self.speed = 0.0
        self.kind = "hold" if hold else "free"

    def power_off(self, position: int, velocity: int) -> None:
        """The power stage goes off: the joint keeps the speed it had and coasts."""
        if self.kind == "driven":
            self.setpoint, self.speed = float(position), float(velocity)
        elif self.kind == "hold":
            self.speed = 0.0
        self.kind = "free"

    def step(self, target: int, use_profile: bool) -> tuple[float, float | None, bool]:
        """One control step on from the last.

        Args:
            target: the drive's target, followed when driven.
            use_profile: whether a driven joint goes through the profile (pp).

        Returns:
            Where the joint should go (m or rad); where a ramp or coasting has it now
            (increments), None when driven; whether a ramp ended in this step.
        """
        joint = self.joint
        if self.kind == "driven":
            goal = joint.from_increments(target)
            if use_profile and self._profile is not None:
                return self._profile.step(goal), None, False
            return goal, None, False
        dt = self.dt
        halted = False
        if self.kind == "ramp":
            v = self.speed
            v_new = math.copysign(max(abs(v) - self._deceleration * dt, 0.0), v)
            self.setpoint += 0.5 * (v + v_new) * dt
            self.speed = v_new
            halted = v_new == 0.0
        elif self.kind == "free" and self.speed:
            self.setpoint += self.speed * dt
            ends = sorted(joint.to_increments(s * joint.hard_limit) for s in (-1, 1))
            if not ends[0] < self.setpoint < ends[1]:
                # An end stop takes the rest of the speed.
                self.setpoint = min(max(self.setpoint, ends[0]), ends[1])
                self.speed = 0.0
        return joint.from_increments(self.setpoint), self.setpoint, halted
