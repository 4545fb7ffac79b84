"""The two-player tasks as PettingZoo games, where both sides learn.

Needs the ``distributed`` extra (PettingZoo); the rest of the package never imports it.
"""

try:
    import pettingzoo  # noqa: F401
except ImportError as err:
    raise ImportError(
        "foosball_gym.multiagent needs PettingZoo, which comes with the 'distributed' extra: "
        'pip install -e ".[distributed]" in the clone'
    ) from err

from foosball_gym.multiagent.parallel import AGENTS, GAME_IDS, FoosballParallelEnv, parallel_env

__all__ = ["AGENTS", "GAME_IDS", "FoosballParallelEnv", "parallel_env"]
