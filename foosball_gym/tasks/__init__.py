"""The foosball tasks, with no simulator behind them; :mod:`foosball_gym.registration` says
which environment id plays which."""

from foosball_gym.tasks.base import Start, Task, clear_of_ball
from foosball_gym.tasks.block import BlockTask
from foosball_gym.tasks.full_game import FullGameTask
from foosball_gym.tasks.keeper_vs_keeper import KeeperVsKeeperTask
from foosball_gym.tasks.score import ScoreTask

__all__ = [
    "BlockTask",
    "FullGameTask",
    "KeeperVsKeeperTask",
    "ScoreTask",
    "Start",
    "Task",
    "clear_of_ball",
]
