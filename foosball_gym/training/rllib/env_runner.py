"""What runs in RLlib's env runners: the game, which module plays which side, and the record
of each game's result.

The env runners' processes import this module by name: the package must be installed on
every node of a cluster.
"""

from __future__ import annotations

import random
from collections.abc import Mapping
from typing import Any

from foosball_gym.training.selfplay.rule import game_result

LEARNER = "learner"
HOME, AWAY = "home", "away"
# The name the game is registered under with Ray.
ENV_NAME = "foosball_selfplay"


def opponent_id(generation: int) -> str:
    """The module id of the snapshot of ``generation``."""
    return f"opponent_{generation:04d}"


def make_game(env_config: Mapping[str, Any]) -> Any:
    """The RLlib multi-agent env of ``env_config["env_id"]`` (an RLlib env creator)."""
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    from foosball_gym.multiagent import parallel_env

    return ParallelPettingZooEnv(
        parallel_env(env_config["env_id"], **dict(env_config.get("env_kwargs", {})))
    )


def map_agent(agent_id: str, episode: Any, *, opponents: tuple[str, ...], **_: Any) -> str:
    """The learner plays home; away is an opponent drawn from the pool, once per episode."""
    if agent_id == HOME:
        return LEARNER
    return random.choice(opponents)


def record_game(*, episode: Any, metrics_logger: Any, **_: Any) -> None:
    """Log the learner's result of each finished game, for the replacement rule."""
    info = episode.get_infos(-1).get(HOME)
    if info is not None:
        # A series, not a mean: the rule looks at the last `window` games one by one.
        metrics_logger.log_value("selfplay_games", game_result(info), reduce="item_series")
