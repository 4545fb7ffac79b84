"""Training and loading policies with Stable-Baselines3: self-play, runs, shipped policies.

Most of it needs the ``train`` extra: ``pip install "foosball_gym[train]"``. A run's
configuration (:mod:`.config`) and file names (:mod:`.files`) do not, so the CLI builds its
options and reads a run directory on the base install; the names below import on first use,
raising :func:`require_train_extra`'s message where the extra is missing.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from foosball_gym.training.models import load_policy
    from foosball_gym.training.selfplay import (
        OpponentActionWrapper,
        SelfPlayCallback,
        SelfPlayVecEnv,
    )
    from foosball_gym.training.snapshot import PolicySnapshot

_LAZY = {
    "load_policy": "models",
    "OpponentActionWrapper": "selfplay",
    "PolicySnapshot": "snapshot",
    "SelfPlayCallback": "selfplay",
    "SelfPlayVecEnv": "selfplay",
}

__all__ = [
    "OpponentActionWrapper",
    "PolicySnapshot",
    "SelfPlayCallback",
    "SelfPlayVecEnv",
    "load_policy",
    "require_train_extra",
]


def require_train_extra() -> None:
    """Raise ImportError naming the ``train`` extra where Stable-Baselines3 or PyTorch is missing.

    Call it before importing the modules that need them, for this message instead of a bare
    "No module named 'torch'".
    """
    try:
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError as err:
        raise ImportError(
            f"foosball_gym.training needs Stable-Baselines3 and PyTorch ({err.name} is missing);"
            ' install them with: pip install torch==2.13.0 && pip install "foosball_gym[train]"'
        ) from err


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    require_train_extra()
    return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
