"""Foosball environments for Gymnasium on PyBullet.

Importing the package registers the environment ids listed in :data:`ENV_IDS`.
"""

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

for _id, _entry, _steps in _ENVS:
    if _id not in registry:
        register(id=_id, entry_point=_entry, max_episode_steps=_steps)

__all__ = ["ENV_IDS", "__version__"]
