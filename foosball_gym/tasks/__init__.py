"""The foosball tasks, by registered environment id, with no simulator behind them."""

from foosball_gym.tasks.base import Start, Task, clear_of_ball, split_options
from foosball_gym.tasks.block import BlockTask
from foosball_gym.tasks.full_game import FullGameTask
from foosball_gym.tasks.keeper_vs_keeper import KeeperVsKeeperTask
from foosball_gym.tasks.registry import TASKS, interface_of, make_task, task_interface
from foosball_gym.tasks.score import ScoreTask

__all__ = [
    "TASKS",
    "BlockTask",
    "FullGameTask",
    "KeeperVsKeeperTask",
    "ScoreTask",
    "Start",
    "Task",
    "clear_of_ball",
    "interface_of",
    "make_task",
    "split_options",
    "task_interface",
]
