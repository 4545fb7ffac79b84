"""The tables of contacts measured in the simulator that scripted play aims with (deflections,
volleys): each a ``.npz`` of directions beside the physics revision it was measured on."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np


@cache
def load(path: Path) -> tuple[np.ndarray, int]:
    """A measured table's directions (degrees) and its physics revision, read once."""
    with np.load(path) as data:
        return data["out_deg"], int(data["physics_revision"])
