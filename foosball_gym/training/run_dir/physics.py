"""The record of the physics a run was trained on, and the warning where a model meets other.

A run's ``config.json`` (and an exported RLlib policy's ``policy.json``) records under
``"physics"`` the revision of the simulated physics it trained on; loading or resuming it on
another revision warns with :class:`PhysicsMismatchWarning`.
"""

from __future__ import annotations

from importlib import metadata
from typing import Any

from foosball_gym.registration import __version__
from foosball_gym.table import PHYSICS_REVISION

# Runs from before config.json recorded its physics were all trained on the first revision.
LEGACY_PHYSICS_REVISION = 1


class PhysicsMismatchWarning(UserWarning):
    """A model or run was trained on another revision of the simulated physics than this one."""


def physics_record() -> dict[str, Any]:
    """The physics this installation simulates, as a run's ``config.json`` records it.

    ``revision`` is :data:`foosball_gym.table.PHYSICS_REVISION`, the one that decides whether
    a model meets the physics it was trained on; the package and PyBullet versions are there
    to trace a difference the revision does not explain.
    """
    try:
        pybullet = metadata.version("pybullet")
    except metadata.PackageNotFoundError:
        pybullet = None
    return {
        "revision": PHYSICS_REVISION,
        "package_version": __version__,
        "pybullet": pybullet,
    }


def recorded_physics_revision(config: dict[str, Any] | None) -> int:
    """The physics revision a run's ``config.json`` (as a dict, or None) says it trained on."""
    physics = (config or {}).get("physics")
    if isinstance(physics, dict) and physics.get("revision") is not None:
        return int(physics["revision"])
    return LEGACY_PHYSICS_REVISION


def physics_mismatch(config: dict[str, Any] | None, name: str) -> str | None:
    """Why ``name``, trained as ``config`` records, may not behave as it did in training; None
    where it was trained on the current physics."""
    recorded = recorded_physics_revision(config)
    if recorded == PHYSICS_REVISION:
        return None
    if "physics" in (config or {}):
        trained = f"{name} was trained on physics revision {recorded}"
    else:
        trained = (
            f"{name} records no physics revision, so it was trained on revision {recorded} "
            "(the record was introduced after that revision)"
        )
    return (
        f"{trained}, but foosball_gym {__version__} simulates physics revision "
        f"{PHYSICS_REVISION}: its results may differ from those it reached in training. "
        "Retraining it on the current physics is advised."
    )
