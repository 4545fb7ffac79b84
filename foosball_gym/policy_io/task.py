"""What a task's policy sees and commands, with no simulator behind it.

A :class:`TaskInterface` holds a task's observation builder and the mapping from its actions to
joint targets. The environment uses it, and so does the real table: both turn a table state
into the same vector and an action into the same targets.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.policy_io.observations import ObservationBuilder, ObservationOptions

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


def action_joints(
    rods: Sequence[str], joints: str
) -> tuple[tuple[Joint, ...], tuple[float, ...], tuple[Joint, ...]]:
    """The joints an action over ``rods`` drives (rod by rod, prismatic first), the factor from
    an action in [-1, 1] to each joint's target, and the joints no action drives."""
    driven, scales, held = [], [], []
    for name in rods:
        driven.append((name, "slide"))
        scales.append(table.rod(name).slide_limit)
        if joints == "both":
            driven.append((name, "spin"))
            scales.append(table.SPIN_LIMIT)
        else:
            held.append((name, "spin"))
    return tuple(driven), tuple(scales), tuple(held)


def residual_action(baseline: Any, scale: Any, correction: Any) -> np.ndarray:
    """The action a residual policy sends: its baseline's action plus ``scale`` (one number,
    or one for each entry of the action) times its correction, clipped to [-1, 1]. In double
    precision wherever it is made (the environment's ``residual`` option, a loaded residual
    model): a corner kick turns a rounding difference into another shot."""
    base = np.asarray(baseline, dtype=np.float64)
    scale = np.asarray(scale, dtype=np.float64)
    return np.clip(base + scale * np.asarray(correction, dtype=np.float64), -1.0, 1.0)


def residual_scale(value: Any) -> float | tuple[float, ...]:
    """The environment option ``residual`` as a run's configuration records it (a number, a
    list of one for each entry of the action, or nothing): 0.0 where it is off."""
    if isinstance(value, list | tuple | np.ndarray):
        scales = tuple(float(v) for v in value)
        return scales if any(scales) else 0.0
    return float(value or 0.0)


def check_action(action: Any, n: int, what: str = "action") -> list[float]:
    """``action`` as ``n`` floats clipped to [-1, 1], or a ValueError saying what is wrong."""
    if isinstance(action, np.ndarray) and action.dtype.kind in "biuf":
        # What a policy gives, the common case: one conversion, no copies.
        values = action.ravel().tolist()
    else:
        try:
            values = action.tolist() if isinstance(action, np.ndarray) else action
            flat = np.ravel(values) if not isinstance(values, float) else np.array([values])
            # float() would take "0.5" and drop an imaginary part: only real numbers are
            # actions.
            if flat.dtype.kind not in "biuf":
                raise TypeError
            values = [float(v) for v in flat]
        except (TypeError, ValueError):
            raise ValueError(f"{what} must be {n} number(s) in [-1, 1], got {action!r}") from None
    if len(values) != n:
        raise ValueError(f"{what} must have {n} value(s) in [-1, 1], got {len(values)}: {action!r}")
    out = []
    for v in values:
        if v != v or v in (math.inf, -math.inf):
            raise ValueError(f"{what} must be finite, got {values}")
        out.append(-1.0 if v < -1.0 else 1.0 if v > 1.0 else float(v))
    return out


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
        slide_around_ball: the half width (m) of the band around the observed ball that a
            slide action spans; 0.0: the rod's travel (the environment's option).
        slide_skip: how far (m) to its side of the ball a slide action other than 0 starts
            (the environment's option ``slide_skip``); 0.0: at the ball.
    """

    layout: Layout
    builder: ObservationBuilder
    action_joints: tuple[Joint, ...]
    action_scales: tuple[float, ...]
    held_joints: tuple[Joint, ...]
    slide_around_ball: float = 0.0
    slide_skip: float = 0.0

    @classmethod
    def create(
        cls, layout: Layout, extras: Sequence[str], options: ObservationOptions
    ) -> TaskInterface:
        builder = ObservationBuilder(
            layout.rods, layout.controlled, layout.joints, layout.opponent, extras, options
        )
        return cls(layout, builder, *action_joints(layout.controlled, layout.joints))

    @property
    def n_actions(self) -> int:
        return len(self.action_joints)

    def table_action(
        self, action: Sequence[float], observation: Sequence[float] | np.ndarray
    ) -> list[float]:
        """``action``, answering ``observation``, as the action over the rods' travel that
        :meth:`action_to_targets` maps: with ``slide_around_ball``, a slide entry ``a`` brings
        the rod's figurine nearest ``ball_y + a * slide_around_ball`` onto it (plus or minus
        ``slide_skip`` as ``a`` is above or below 0), as far as the rod slides; otherwise
        the action itself."""
        out = list(action)
        band = self.slide_around_ball
        if not band:
            return out
        ball_at, slides = self._slides_around_ball
        ball_y = float(observation[ball_at])
        skip = self.slide_skip
        for i, rod in slides:
            a = out[i]
            offset = a * band + (skip if a > 0 else -skip if a < 0 else 0.0)
            out[i] = table.slide_for(rod, ball_y + offset) / rod.slide_limit
        return out

    @functools.cached_property
    def _slides_around_ball(self) -> tuple[int, tuple[tuple[int, table.Rod], ...]]:
        """Where the observation holds the ball's y, and each slide entry's place in the action
        with its rod: looked up once, not at every step."""
        slides = tuple(
            (i, table.rod(name))
            for i, (name, kind) in enumerate(self.action_joints)
            if kind == "slide"
        )
        return self.builder.names.index("ball_y"), slides

    def action_to_targets(self, action: Sequence[float]) -> dict[Joint, float]:
        """Joint targets (m, rad) for an action, clipped to [-1, 1] as the env does."""
        targets = {joint: 0.0 for joint in self.held_joints}
        for joint, scale, a in zip(
            self.action_joints, self.action_scales, check_action(action, self.n_actions)
        ):
            targets[joint] = scale * a
        return targets
