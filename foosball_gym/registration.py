"""The package's version and the environment ids it registers with Gymnasium.

Kept apart from the package's ``__init__`` so that modules needing either import this one, not
the package, which also offers :func:`foosball_gym.load_policy` from the training side.
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

__version__ = "0.1.0"

# id, entry point, max_episode_steps (60 Hz control steps)
_ENVS = (
    ("Foosball-Block-v0", "foosball_gym.envs.block:BlockEnv", 90),
    ("Foosball-Score-v0", "foosball_gym.envs.score:ScoreEnv", 180),
    ("Foosball-KeeperVsKeeper-v0", "foosball_gym.envs.keeper_vs_keeper:KeeperVsKeeperEnv", 1800),
    ("Foosball-FullGame-v0", "foosball_gym.envs.full_game:FullGameEnv", 3600),
)

ENV_IDS: tuple[str, ...] = tuple(env_id for env_id, _, _ in _ENVS)


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` that Gymnasium does not know yet."""
    for env_id, entry_point, steps in _ENVS:
        if env_id not in registry:
            register(id=env_id, entry_point=entry_point, max_episode_steps=steps)
