"""What `foosball play` puts between a policy and the drives, put between the policy and the
simulated drives: the environment option ``safety_layer``.

On a table every target goes through the safety layer's
:class:`~foosball_gym.policy_io.target_limits.TargetLimiter` before a drive sees it: kept
inside the joint's limit less a margin, and moved towards at no more than the joint's top
speed and acceleration, braking in time to stop on it. The drive then follows that moving
target. An environment that hands the policy's target to the simulated drive at once lets the
rod get there sooner than any table does. The limiter here is the very one the play stack
runs, with the limits of the simulated table (``foosball play --table sim``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from foosball_gym.policy_io.target_limits import JointLimits, TargetLimiter
from foosball_gym.policy_io.task import Joint


def check_safety_layer(value: Any, estimated_state: bool) -> bool:
    """``safety_layer`` as a bool; None follows ``estimated_state``. A ValueError says what
    is allowed."""
    if value is None:
        return bool(estimated_state)
    if isinstance(value, bool):
        return value
    raise ValueError(
        f"safety_layer must be None (on with estimated_state), True or False; got {value!r}"
    )


class SafetyLayer:
    """The play stack's target limiter for each joint the learner's action drives.

    Args:
        driven: the joints the action drives, in action order.
        scales: the factor from an action in [-1, 1] to each driven joint's target.
        dt: the control period (s).
    """

    def __init__(self, driven: Sequence[Joint], scales: Sequence[float], dt: float) -> None:
        self.scales = [float(s) for s in scales]
        self.limiters = [TargetLimiter(JointLimits.simulated(*j), dt) for j in driven]

    def reset(self, positions: Sequence[float]) -> None:
        """Start from rods at rest at ``positions`` (m, rad; in action order, as the table
        reads them), as the play stack starts from the drives' positions."""
        for limiter, p in zip(self.limiters, positions):
            limiter.reset(p)

    def shape(self, action: Sequence[float]) -> list[float]:
        """The action the drives are sent this step: each target as the limiter lets it go,
        in the action's own units."""
        out = []
        for limiter, s, a in zip(self.limiters, self.scales, action):
            value = limiter.step(s * a) / s
            out.append(-1.0 if value < -1.0 else 1.0 if value > 1.0 else value)
        return out
