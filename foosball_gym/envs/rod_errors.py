"""How a real table misreads its own rods: calibration offsets and angle noise.

A real table knows where its rods are from its drives' encoders, zeroed when the table is
calibrated. A zero set a little off puts every reading of that joint, and every target sent to
it, off by the same amount for as long as the table runs: the policy sees its rod at
``q + offset`` and, asking for ``a``, gets the rod to ``a - offset``. An angle read through a
flexible rod or a coarse encoder also wobbles from one reading to the next. Both are drawn
from the environment's generator, so a seed repeats them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from foosball_gym.policy_io.task import Joint
from foosball_gym.tasks.serves import check_range, within

#: The largest calibration offset each option allows: m for slides, rad for angles.
OFFSET_LIMITS = {"slide_offset_range": 0.05, "angle_offset_range": 0.5}
#: The largest standard deviation of ``rod_angle_noise`` (rad).
ANGLE_NOISE_LIMIT = 0.5


def check_angle_noise(value: Any) -> float:
    """``rod_angle_noise`` as a float, or a ValueError saying what it allows."""
    std = within(value, ANGLE_NOISE_LIMIT)
    if math.isnan(std):
        raise ValueError(
            f"rod_angle_noise must be a standard deviation in [0, {ANGLE_NOISE_LIMIT}] rad "
            f"(0: off), got {value!r}"
        )
    return std


class RodErrors:
    """The errors of the learner's own joint readings and commands, for one environment.

    Args:
        joints: the joints the learner's action drives, in action order.
        rods: the rods in play, in the order of the joint arrays (all slides, then all spins).
        slide_offset_range, angle_offset_range: each driven joint's calibration offset (m,
            rad), drawn uniformly at every reset; None: none.
        rod_angle_noise: the standard deviation (rad) of the noise on each observed angle of
            a driven spin, drawn afresh at every observation; 0: none.
    """

    def __init__(
        self,
        joints: Sequence[Joint],
        rods: Sequence[str],
        slide_offset_range: Any,
        angle_offset_range: Any,
        rod_angle_noise: Any,
    ) -> None:
        self.ranges: dict[str, tuple[float, float]] = {}
        for name, value in (
            ("slide_offset_range", slide_offset_range),
            ("angle_offset_range", angle_offset_range),
        ):
            if value is not None:
                limit = OFFSET_LIMITS[name]
                self.ranges[name] = check_range(name, value, -limit, limit)
        self.angle_noise = check_angle_noise(rod_angle_noise)
        turning = any(kind == "spin" for _, kind in joints)
        for name, on in (
            ("angle_offset_range", "angle_offset_range" in self.ranges),
            ("rod_angle_noise", self.angle_noise > 0),
        ):
            if on and not turning:
                raise ValueError(
                    f"{name} needs a rod that turns: this task's action drives no rod's spin"
                )
        self.joints = tuple(joints)
        n = len(rods)
        # Each driven joint's place in the joint arrays.
        self._slots = [
            list(rods).index(rod) + (n if kind == "spin" else 0) for rod, kind in self.joints
        ]
        self._spin_slots = [
            slot for slot, (_, kind) in zip(self._slots, self.joints) if kind == "spin"
        ]
        #: Each driven joint's offset this episode, in action order.
        self.offsets = [0.0] * len(self.joints)

    @property
    def on(self) -> bool:
        return bool(self.ranges) or self.angle_noise > 0

    def draw(self, rng: np.random.Generator) -> dict[str, float]:
        """This episode's offsets: one uniform draw per driven joint of each kind that has a
        range on (slides, then spins, in action order); returns them by name
        (``slide_offset_<rod>``, ``angle_offset_<rod>``)."""
        drawn: dict[str, float] = {}
        for name, bounds in self.ranges.items():
            kind = "slide" if name == "slide_offset_range" else "spin"
            entries = [i for i, (_, k) in enumerate(self.joints) if k == kind]
            for i, value in zip(entries, rng.uniform(*bounds, size=len(entries))):
                self.offsets[i] = float(value)
                drawn[f"{name.removesuffix('_range')}_{self.joints[i][0]}"] = float(value)
        return drawn

    def observed(self, positions: Sequence[float], rng: np.random.Generator) -> list[float]:
        """The joint positions as the table reads them: each driven joint off by its offset,
        each driven angle with fresh noise."""
        pos = list(positions)
        for slot, offset in zip(self._slots, self.offsets):
            pos[slot] += offset
        if self.angle_noise > 0:
            for slot, noise in zip(
                self._spin_slots, rng.normal(0.0, self.angle_noise, size=len(self._spin_slots))
            ):
                pos[slot] += float(noise)
        return pos
