"""The foosball tasks as Gymnasium environments."""

from foosball_gym.envs.base import FoosballEnv
from foosball_gym.envs.block import BlockEnv

__all__ = ["BlockEnv", "FoosballEnv"]
