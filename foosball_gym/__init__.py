"""Foosball environments for Gymnasium on PyBullet.

Importing the package registers the environment ids listed in :data:`ENV_IDS`.
"""

from __future__ import annotations

from typing import Any

from foosball_gym import old_paths
from foosball_gym.registration import ENV_IDS, __version__, register_envs

register_envs()
# The real-table packages' names from before they moved into real_table/ (for one release).
old_paths.install()


def load_policy(spec: Any, trust: bool = False) -> Any:
    """A trained policy, ready to act: ``policy(obs) -> action`` with its normalisation.

    ``spec`` is a run directory, a model ``.zip``, an RL Zoo run or ``builtin:NAME``; see
    :func:`foosball_gym.training.loading.load_policy` (the ``train`` extra), which this calls.
    """
    from foosball_gym.training.loading import load_policy as load

    return load(spec, trust=trust)


__all__ = ["ENV_IDS", "__version__", "load_policy"]
