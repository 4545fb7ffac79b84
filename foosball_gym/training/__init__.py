"""Training and evaluation with Stable-Baselines3: self-play, runs, loading policies.

Needs the ``train`` extra: ``pip install "foosball_gym[train]"``.
"""

from __future__ import annotations

try:
    import stable_baselines3  # noqa: F401
    import torch  # noqa: F401
except ImportError as err:  # pragma: no cover - depends on what is installed
    raise ImportError(
        f"foosball_gym.training needs Stable-Baselines3 and PyTorch ({err.name} is missing); "
        'install them with: pip install torch==2.13.0 && pip install "foosball_gym[train]"'
    ) from err

from foosball_gym.training.selfplay import (
    OpponentActionWrapper,
    SelfPlayCallback,
    SelfPlayVecEnv,
)
from foosball_gym.training.snapshot import PolicySnapshot

__all__ = ["OpponentActionWrapper", "PolicySnapshot", "SelfPlayCallback", "SelfPlayVecEnv"]
