"""The record of the physics a run was trained on, and the warning where a model meets other.

A run's ``config.json`` (and an exported RLlib policy's ``policy.json``) records under
``"physics"`` the revision of the simulated physics it trained on; loading or resuming it on
another revision warns with :class:`PhysicsMismatchWarning`. A model with no record at all (one
trained elsewhere, such as an RL Zoo run, or a zip without its run) warns with
:class:`UnknownPhysicsWarning`: its revision is unknown, not the first.
"""

from __future__ import annotations

import warnings
from importlib import metadata
from typing import Any

from foosball_gym.registration import __version__
from foosball_gym.table import PHYSICS_REVISION

# Runs from before config.json recorded its physics were all trained on the first revision.
LEGACY_PHYSICS_REVISION = 1


class PhysicsMismatchWarning(UserWarning):
    """A model or run was trained on another revision of the simulated physics than this one."""


class UnknownPhysicsWarning(PhysicsMismatchWarning):
    """A model records no physics at all, so whether it was trained on this revision is unknown.

    A kind of :class:`PhysicsMismatchWarning`, so that a filter on that one covers it too.
    """


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
    where it was trained on the current physics.

    ``config`` is a run's ``config.json``; one without ``"physics"`` is a run from before the
    record and was trained on the first revision. None (no run's ``config.json`` at all) gives
    :func:`physics_unknown`'s message: :func:`warn_physics` warns with the category that fits.
    """
    if config is None:
        return physics_unknown(name)
    recorded = recorded_physics_revision(config)
    if recorded == PHYSICS_REVISION:
        return None
    if "physics" in config:
        trained = f"{name} was trained on physics revision {recorded}"
    else:
        trained = (
            f"{name} is a run from before runs recorded their physics, so it was trained on "
            f"revision {recorded}"
        )
    return (
        f"{trained}, but foosball_gym {__version__} simulates physics revision "
        f"{PHYSICS_REVISION}: its results may differ from those it reached in training. "
        "Retraining it on the current physics is advised."
    )


def physics_unknown(name: str) -> str:
    """Why ``name``, which records no physics (no run's ``config.json`` beside it), may not
    behave as it did in training."""
    return (
        f"{name} records no physics revision (it has no foosball_gym run's config.json), so the "
        f"revision it was trained on is unknown; foosball_gym {__version__} simulates physics "
        f"revision {PHYSICS_REVISION}: if it was trained on another, its results may differ "
        "from those it reached in training."
    )


def warn_physics(config: dict[str, Any] | None, name: str, stacklevel: int = 2) -> None:
    """Warn where ``name``, trained as ``config`` records (None: no record at all), may meet
    other physics than it was trained on: :class:`PhysicsMismatchWarning`, or
    :class:`UnknownPhysicsWarning` where there is no record.

    Args:
        config: the run's ``config.json`` as a dict, or None where the model has none.
        name: what the message calls the model.
        stacklevel: as :func:`warnings.warn`'s, counted from the caller of this function.
    """
    if config is None:
        warnings.warn(physics_unknown(name), UnknownPhysicsWarning, stacklevel=stacklevel + 1)
        return
    mismatch = physics_mismatch(config, name)
    if mismatch:
        warnings.warn(mismatch, PhysicsMismatchWarning, stacklevel=stacklevel + 1)
