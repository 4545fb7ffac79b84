"""What a task's policy sees and commands, with no simulator behind it.

A :class:`TaskInterface` holds a task's observation builder and the mapping from its actions to
joint targets. The environment uses it, and so does the real table: both turn a table state
into the same vector and an action into the same targets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import gymnasium as gym

from foosball_gym import table as T
from foosball_gym.interface.observations import ObservationBuilder, ObservationOptions

Joint = tuple[str, str]  # (rod name, "slide" | "spin")


@dataclass(frozen=True)
class Layout:
    """Which rods a task puts in play and who moves them.

    Attributes:
        controlled: home rods the learner drives, keeper first.
        joints: ``"slide"`` (prismatic only) or ``"both"``: the learner's action joints.
        opponent: away rods an opponent policy drives (the mirror of ``controlled``).
        static: rods held still at their start position (obstacles).
    """

    controlled: tuple[str, ...]
    joints: str
    opponent: tuple[str, ...] = ()
    static: tuple[str, ...] = ()

    @property
    def rods(self) -> tuple[str, ...]:
        return self.controlled + self.opponent + self.static


@dataclass(frozen=True)
class TaskInterface:
    """A task's observation builder and action mapping.

    Attributes:
        layout: the task's rods.
        builder: turns joint values and the ball into the observation vector.
        action_joints: the joint each action entry drives, in action order.
        action_scales: the factor from an action in [-1, 1] to that joint's target (m or rad).
        held_joints: joints of the controlled rods that no action drives (held at 0, e.g. the
            keeper's revolute joint in Block).
    """

    layout: Layout
    builder: ObservationBuilder
    action_joints: tuple[Joint, ...]
    action_scales: tuple[float, ...]
    held_joints: tuple[Joint, ...]

    @classmethod
    def create(
        cls, layout: Layout, extras: Sequence[str], options: ObservationOptions
    ) -> TaskInterface:
        builder = ObservationBuilder(
            layout.rods, layout.controlled, layout.joints, layout.opponent, extras, options
        )
        joints, scales, held = [], [], []
        for name in layout.controlled:
            joints.append((name, "slide"))
            scales.append(T.rod(name).slide_limit)
            if layout.joints == "both":
                joints.append((name, "spin"))
                scales.append(T.SPIN_LIMIT)
            else:
                held.append((name, "spin"))
        return cls(layout, builder, tuple(joints), tuple(scales), tuple(held))

    @property
    def n_actions(self) -> int:
        return len(self.action_joints)

    def action_to_targets(self, action: Sequence[float]) -> dict[Joint, float]:
        """Joint targets (m, rad) for an action, clipped to [-1, 1] as the env does."""
        if len(action) != self.n_actions:
            raise ValueError(f"action must have {self.n_actions} values, got {len(action)}")
        targets = {joint: 0.0 for joint in self.held_joints}
        for joint, scale, a in zip(self.action_joints, self.action_scales, action):
            targets[joint] = scale * min(max(float(a), -1.0), 1.0)
        return targets


def task_interface(env_id: str, env_kwargs: dict[str, Any] | None = None) -> TaskInterface:
    """The interface of a registered environment with these options, built without a simulator."""
    if env_id not in gym.registry:
        import foosball_gym

        raise ValueError(
            f"unknown environment {env_id!r}; registered: {', '.join(foosball_gym.ENV_IDS)}"
        )
    spec = gym.spec(env_id)
    cls = gym.envs.registration.load_env_creator(spec.entry_point)
    return cls.task_interface(**{**spec.kwargs, **(env_kwargs or {})})
