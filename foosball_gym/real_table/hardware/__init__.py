"""A table's configuration, its CANopen drives and the safety layer in front of them.

``config`` and ``safety`` need no CAN library; :class:`TableDrives` and :class:`Cia402Drive`
need python-can and canopen (``pip install -e '.[hardware]'``) and are imported on
first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from foosball_gym.real_table.hardware.config import (
    BusConfig,
    ConfigError,
    JointConfig,
    TableConfig,
    load_config,
    save_config,
    shipped_table,
)
from foosball_gym.real_table.hardware.safety import (
    DriveFault,
    SafetyError,
    UnsafeCommand,
    WatchdogTripped,
)

if TYPE_CHECKING:
    from foosball_gym.real_table.hardware.cia402 import Cia402Drive
    from foosball_gym.real_table.hardware.drives import TableDrives

__all__ = [
    "BusConfig",
    "Cia402Drive",
    "ConfigError",
    "DriveFault",
    "JointConfig",
    "SafetyError",
    "TableConfig",
    "TableDrives",
    "UnsafeCommand",
    "WatchdogTripped",
    "load_config",
    "save_config",
    "shipped_table",
]

_LAZY = {"TableDrives": "drives", "Cia402Drive": "cia402"}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    try:
        import canopen  # noqa: F401
    except ImportError:
        raise ImportError(
            f"{name} needs python-can and canopen: pip install -e '.[hardware]'"
        ) from None
    from importlib import import_module

    return getattr(import_module(f"{__name__}.{_LAZY[name]}"), name)
