"""The simulator's physics options, checked without the simulator (the real table builds a
task's interface, options and all, where pybullet may not be installed)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from foosball_gym import table
from foosball_gym.tasks.serves import check_range

#: Each domain randomisation option, with the bounds its range must keep.
RANDOMISATION_BOUNDS = {
    "ball_friction_range": (0.0, 10.0),
    "ball_restitution_range": (0.0, 1.0),
    "ball_mass_range": (1e-4, 1.0),
    "drive_gain_range": (1e-3, 10.0),
    "rolling_resistance_range": (0.0, 0.5),
    # Factors on each drive's own limits. A top speed above the rated one is not offered: the
    # simulated joints are built for the rated speeds (Bullet caps a spin at 1.1 times its).
    "drive_speed_range": (0.1, 1.0),
    "drive_accel_range": (0.1, 2.0),
}
#: The randomised quantities drawn once for each drive (the others once for the whole table).
PER_DRIVE = ("drive_speed", "drive_accel")


def check_physics(
    physics_hz: object,
    control_hz: object,
    contact_travel: object = table.CONTACT_TRAVEL,
    rolling_resistance: object = table.ROLLING_RESISTANCE,
) -> tuple[int, int, float, float]:
    """Validate the physics options; returns them as (int, int, float, float).

    Raises:
        ValueError: naming the option and the values it allows.
    """
    physics_hz = _rate("physics_hz", physics_hz)
    control_hz = _rate("control_hz", control_hz)
    if physics_hz < control_hz:
        raise ValueError(
            f"physics_hz ({physics_hz}) must be at least control_hz ({control_hz}): the "
            f"physics cannot step more coarsely than the controller acts"
        )
    if physics_hz % control_hz:
        raise ValueError(
            f"physics_hz ({physics_hz}) must be a whole multiple of control_hz ({control_hz}), "
            f"e.g. {control_hz * max(1, round(physics_hz / control_hz))}"
        )
    numbers = []
    for name, value, low, high in (
        ("contact_travel", contact_travel, 1e-4, 0.02),
        ("rolling_resistance", rolling_resistance, 0.0, 0.5),
    ):
        try:
            # Whatever was given: float() is what tells whether it is a number.
            number = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            number = math.nan
        if isinstance(value, bool) or not low <= number <= high:
            unit = " m" if name == "contact_travel" else ""
            raise ValueError(f"{name} must be a number in [{low}, {high}]{unit}, got {value!r}")
        numbers.append(number)
    contact, rolling = numbers
    return physics_hz, control_hz, contact, rolling


def _rate(name: str, value: object) -> int:
    """``value`` as a positive whole number of Hz.

    Raises:
        ValueError: naming the option if it is not one.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value <= 0:
        raise ValueError(f"{name} must be a positive integer (Hz), got {value!r}")
    return int(value)


#: The physics options every environment takes, with their defaults, in check_physics' order.
PHYSICS_DEFAULTS = {
    "physics_hz": table.PHYSICS_HZ,
    "control_hz": table.CONTROL_HZ,
    "contact_travel": table.CONTACT_TRAVEL,
    "rolling_resistance": table.ROLLING_RESISTANCE,
}


def check_randomisation(ranges: dict[str, Any]) -> dict[str, tuple[float, float]]:
    """The domain randomisation options that are on (not None), each a checked range."""
    return {
        name: check_range(name, value, *RANDOMISATION_BOUNDS[name])
        for name, value in ranges.items()
        if value is not None
    }
