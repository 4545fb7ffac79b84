"""The foosball tasks as Gymnasium environments."""

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.envs.block import BlockEnv
from foosball_gym.envs.full_game import FullGameEnv
from foosball_gym.envs.keeper_vs_keeper import KeeperVsKeeperEnv
from foosball_gym.envs.score import ScoreEnv

__all__ = ["BlockEnv", "FoosballEnv", "FullGameEnv", "KeeperVsKeeperEnv", "ScoreEnv"]
