"""What `foosball play` puts between a policy and the drives, put between the policy and the
simulated drives: the environment option ``safety_layer``.

On a table every target goes through the safety layer's
:class:`~foosball_gym.hardware.safety.TargetLimiter` before a drive sees it: kept inside the
joint's limit less a margin, and moved towards at no more than the joint's top speed and
acceleration, braking in time to stop on it. The drive then follows that moving target. An
environment that hands the policy's target to the simulated drive at once lets the rod get
there sooner than any table does, and a policy trained that way reaches late on a table. The
limiter here is the very one the play stack runs, with the limits of the simulated table
(``foosball play --table sim``) or of a table's configuration file.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

from foosball_gym import table
from foosball_gym.hardware.config import ConfigError, JointConfig, TableConfig, load_config
from foosball_gym.hardware.safety import JointLimits, TargetLimiter
from foosball_gym.policy_io.task import Joint


def simulated_joint(
    rod: str, kind: str, node_id: int = 1, increments_per_unit: float = 1.0, direction: int = 1
) -> JointConfig:
    """The configuration of one joint of the simulated table: the safety layer's default
    margin and top speed, and the acceleration the simulated drive reaches (the safety
    layer's default is a guess kept well inside a real drive's, which would make the simulated
    table's rods slower than the environment's)."""
    return JointConfig(
        rod=rod,
        joint=kind,
        node_id=node_id,
        increments_per_unit=increments_per_unit,
        direction=direction,
        max_acceleration=table.drive_acceleration(table.rod(rod), kind),
    )


def check_safety_layer(value: Any, estimated_state: bool) -> TableConfig | bool:
    """``safety_layer`` as False (off), True (the simulated table's limits) or the table
    configuration whose limits to use; None follows ``estimated_state``. A ValueError says
    what is allowed."""
    if value is None:
        return bool(estimated_state)
    if isinstance(value, bool):
        return value
    if isinstance(value, (str, os.PathLike)):
        try:
            return load_config(value)
        except (OSError, ConfigError) as e:
            raise ValueError(
                f"safety_layer: cannot use the table configuration {value!r}: {e}"
            ) from e
    raise ValueError(
        "safety_layer must be None (on with estimated_state), True, False, or the path of a "
        f"table configuration (.yaml) whose limits to use; got {value!r}"
    )


class SafetyLayer:
    """The play stack's target limiter for each joint the learner's action drives.

    Args:
        driven: the joints the action drives, in action order.
        scales: the factor from an action in [-1, 1] to each driven joint's target.
        dt: the control period (s).
        config: the table configuration whose joint limits to use; None: the simulated
            table's.
    """

    def __init__(
        self,
        driven: Sequence[Joint],
        scales: Sequence[float],
        dt: float,
        config: TableConfig | None = None,
    ) -> None:
        if config is not None:
            missing = [j for j in driven if j not in config.joint_keys()]
            if missing:
                have = ", ".join(f"{rod} {kind}" for rod, kind in config.joint_keys())
                raise ValueError(
                    "safety_layer: the table configuration has no drive for "
                    f"{', '.join(f'{rod} {kind}' for rod, kind in missing)}, which this "
                    f"task's action drives; it has {have}"
                )
        self.scales = [float(s) for s in scales]
        self.limiters = [
            TargetLimiter(JointLimits.of(config.joint(j) if config else simulated_joint(*j)), dt)
            for j in driven
        ]

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
