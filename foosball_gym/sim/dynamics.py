"""Domain randomisation's draw: one table's physical parameters for an episode or a serve."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from foosball_gym import table
from foosball_gym.sim.options import PER_DRIVE


class Randomisable(Protocol):
    """What the draw sets on a table (:class:`~foosball_gym.sim.table_sim.TableSim`)."""

    rods: tuple[table.Rod, ...]

    def set_ball_dynamics(
        self,
        *,
        mass: float | None = None,
        friction: float | None = None,
        restitution: float | None = None,
        rolling_resistance: float | None = None,
    ) -> None: ...

    def set_drive_gains(self, slide_gain: float, spin_gain: float) -> None: ...

    def set_drive_limits(self, speed: Sequence[float], accel: Sequence[float]) -> None: ...


def draw_dynamics(
    sim: Randomisable,
    ranges: dict[str, tuple[float, float]],
    rng: np.random.Generator,
    base_gains: tuple[float, float],
    joints: Sequence[tuple[str, str]] | None = None,
) -> dict[str, float]:
    """Draw and set ``sim``'s physical parameters the domain randomisation ``ranges`` give
    (the options named ``*_range``, checked), uniformly, in their order.

    ``drive_gain`` is a factor on ``base_gains`` (slide, spin). ``drive_speed`` and
    ``drive_accel`` are factors on the top speed and the most acceleration of each drive of
    ``joints`` (``(rod, "slide" | "spin")`` pairs; None: every joint in play), one draw per
    drive; the other drives keep their own limits.

    Returns:
        the values drawn, under their quantities' names; a drive's factors as
        ``drive_speed_<rod>_<slide|spin>`` and ``drive_accel_<rod>_<slide|spin>``.
    """
    n = len(sim.rods)
    names = [rod.name for rod in sim.rods]
    if joints is None:
        joints = [(name, kind) for kind in ("slide", "spin") for name in names]
    drawn: dict[str, float] = {}
    factors = {quantity: [1.0] * (2 * n) for quantity in PER_DRIVE}
    for name, bounds in ranges.items():
        quantity = name.removesuffix("_range")
        if quantity not in PER_DRIVE:
            drawn[quantity] = float(rng.uniform(*bounds))
            continue
        for (rod, kind), value in zip(joints, rng.uniform(*bounds, size=len(joints))):
            drawn[f"{quantity}_{rod}_{kind}"] = float(value)
            factors[quantity][names.index(rod) + (n if kind == "spin" else 0)] = float(value)
    sim.set_ball_dynamics(
        friction=drawn.get("ball_friction"),
        restitution=drawn.get("ball_restitution"),
        mass=drawn.get("ball_mass"),
        rolling_resistance=drawn.get("rolling_resistance"),
    )
    if "drive_gain" in drawn:
        slide, spin = base_gains
        sim.set_drive_gains(slide * drawn["drive_gain"], spin * drawn["drive_gain"])
    if any(name.removesuffix("_range") in PER_DRIVE for name in ranges):
        sim.set_drive_limits(factors["drive_speed"], factors["drive_accel"])
    return drawn
