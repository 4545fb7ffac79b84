"""Training and loading policies: self-play, runs of either backend, shipped policies.

The package is split by job:

- :mod:`.config` and :mod:`.config_file`: a run's configuration, the same for both backends;
- :mod:`.run_dir`: a run directory's files, curve, best model and storage, shared by both;
- :mod:`.loading`: loading a policy to play (``load_policy``), without any trainer;
- :mod:`.selfplay`: the replacement rule, its gate, the opponents, matches and the league;
- :mod:`.sb3`: the Stable-Baselines3 backend (``train``);
- :mod:`.rllib`: the Ray RLlib backend (``train_rllib``).

Most of it needs the ``train`` extra: ``pip install -e ".[train]"``. A run's
configuration and its directory's file names do not, so the CLI builds its options and reads
a run directory on the base install; the names below import on first use, raising
:func:`require_train_extra`'s message where the extra is missing.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from foosball_gym.training.loading import load_policy
    from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot
    from foosball_gym.training.sb3.trainer import train
    from foosball_gym.training.selfplay.callback import SelfPlayCallback
    from foosball_gym.training.selfplay.opponents import OpponentActionWrapper, SelfPlayVecEnv

_LAZY = {
    "load_policy": "loading",
    "OpponentActionWrapper": "selfplay.opponents",
    "PolicySnapshot": "loading.sb3_snapshot",
    "SelfPlayCallback": "selfplay.callback",
    "SelfPlayVecEnv": "selfplay.opponents",
    "train": "sb3.trainer",
}

__all__ = [
    "OpponentActionWrapper",
    "PolicySnapshot",
    "SelfPlayCallback",
    "SelfPlayVecEnv",
    "load_policy",
    "require_train_extra",
    "train",
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
            " install them with: pip install torch==2.13.0 --extra-index-url"
            ' https://download.pytorch.org/whl/cpu && pip install -e ".[train]" (in the clone)'
        ) from err


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    require_train_extra()
    return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
