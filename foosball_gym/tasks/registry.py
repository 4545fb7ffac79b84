"""Which task each registered environment id plays, and its interface for given options."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from foosball_gym.policy_io.observations import OBSERVATION_OPTIONS, observation_options
from foosball_gym.policy_io.task import TaskInterface
from foosball_gym.tasks.base import Task, split_options
from foosball_gym.tasks.block import BlockTask
from foosball_gym.tasks.full_game import FullGameTask
from foosball_gym.tasks.keeper_vs_keeper import KeeperVsKeeperTask
from foosball_gym.tasks.score import ScoreTask

TASKS: dict[str, type[Task]] = {
    "Foosball-Block-v0": BlockTask,
    "Foosball-Score-v0": ScoreTask,
    "Foosball-KeeperVsKeeper-v0": KeeperVsKeeperTask,
    "Foosball-FullGame-v0": FullGameTask,
}


def make_task(env_id: str, env_kwargs: dict[str, Any] | None = None) -> tuple[Task, dict[str, Any]]:
    """The task ``env_id`` plays with these options, and the options left for the environment
    (the registration's own keyword arguments and the task's defaults included)."""
    if env_id not in TASKS:
        raise ValueError(f"unknown environment {env_id!r}; registered: {', '.join(TASKS)}")
    registered = gym.spec(env_id).kwargs if env_id in gym.registry else {}
    kwargs = {**registered, **(env_kwargs or {})}
    task_kwargs, rest = split_options(TASKS[env_id], kwargs)
    return TASKS[env_id](**task_kwargs), rest


def interface_of(task: Task, env_kwargs: dict[str, Any]) -> TaskInterface:
    """The task's observation builder and action mapping for the environment's options."""
    options = observation_options(
        bool(task.layout.opponent),
        **{k: env_kwargs[k] for k in OBSERVATION_OPTIONS if k in env_kwargs},
    )
    return TaskInterface.create(task.layout, task.extras, options)


def task_interface(env_id: str, env_kwargs: dict[str, Any] | None = None) -> TaskInterface:
    """The interface of a registered environment with these options, built without a simulator:
    what the real table needs to run a policy trained on the task."""
    return interface_of(*make_task(env_id, env_kwargs))
