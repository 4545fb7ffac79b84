"""The registered environments, one row each, and what is read from them.

:data:`ENVS` is the one table of environment ids: Gymnasium registration, the ``foosball``
command, the training configuration, the real table and the tests all read it. A task's
options and their defaults are its environment class's keyword arguments; the real table reads
them from there to build the task's observation without a simulator.

setup.cfg reads the package's version from here.
"""

from __future__ import annotations

import inspect
import textwrap
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator, register, registry

from foosball_gym.policy_io.observations import OBSERVATION_OPTIONS, observation_options
from foosball_gym.policy_io.task import TaskInterface
from foosball_gym.tasks.base import Task
from foosball_gym.tasks.block import BlockTask
from foosball_gym.tasks.full_game import FullGameTask
from foosball_gym.tasks.keeper_vs_keeper import KeeperVsKeeperTask
from foosball_gym.tasks.score import ScoreTask

if TYPE_CHECKING:
    from foosball_gym.envs.base import FoosballEnv
    from foosball_gym.envs.options import CheckedOptions

__version__ = "0.1.0"


@dataclass(frozen=True)
class EnvEntry:
    """One registered environment.

    Attributes:
        id: its Gymnasium id.
        env: its class as an entry point, ``"module:Class"``: imported when an environment is
            made or its options are read, not when the package is.
        task: the task it plays.
        max_episode_steps: the registered time limit, in control steps (60 Hz by default).
    """

    id: str
    env: str
    task: type[Task]
    max_episode_steps: int


ENVS: tuple[EnvEntry, ...] = (
    EnvEntry("Foosball-Block-v0", "foosball_gym.envs.block:BlockEnv", BlockTask, 90),
    EnvEntry("Foosball-Score-v0", "foosball_gym.envs.score:ScoreEnv", ScoreTask, 180),
    EnvEntry(
        "Foosball-KeeperVsKeeper-v0",
        "foosball_gym.envs.keeper_vs_keeper:KeeperVsKeeperEnv",
        KeeperVsKeeperTask,
        1800,
    ),
    EnvEntry("Foosball-FullGame-v0", "foosball_gym.envs.full_game:FullGameEnv", FullGameTask, 3600),
)

ENV_IDS: tuple[str, ...] = tuple(entry.id for entry in ENVS)
#: The task of each id.
TASKS: Mapping[str, type[Task]] = {entry.id: entry.task for entry in ENVS}
_BY_ID = {entry.id: entry for entry in ENVS}


def register_envs() -> None:
    """Register every id of :data:`ENVS` that Gymnasium does not know yet."""
    for entry in ENVS:
        if entry.id not in registry:
            register(id=entry.id, entry_point=entry.env, max_episode_steps=entry.max_episode_steps)


def check_env_id(env_id: str) -> None:
    """Raise ValueError naming the registered ids where ``env_id`` is not one of them."""
    if env_id not in gym.registry:
        raise ValueError(f"unknown environment {env_id!r}; registered: {', '.join(ENV_IDS)}")


def env_entry(env_id: str) -> EnvEntry:
    """The row of ``env_id``, or a ValueError naming the ids there are."""
    if env_id not in _BY_ID:
        raise ValueError(f"unknown environment {env_id!r}; registered: {', '.join(ENV_IDS)}")
    return _BY_ID[env_id]


def env_class(env_id: str) -> Any:
    """The environment class of ``env_id`` (a :class:`~foosball_gym.envs.base.FoosballEnv`)."""
    return load_env_creator(env_entry(env_id).env)


def env_options(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Every option of ``env_id``'s environment with its value: those given (and any the
    registration adds) over the defaults of the class's signature.

    Raises:
        TypeError: an option the environment does not take, naming those it does.
    """
    cls = env_class(env_id)
    registered = gym.spec(env_id).kwargs if env_id in registry else {}
    given = {**registered, **(env_kwargs or {})}
    cls.check_option_names(given)
    return {**cls.option_defaults(), **given}


def make_task(
    env_id: str, env_kwargs: Mapping[str, Any] | None = None
) -> tuple[Task, dict[str, Any]]:
    """The task ``env_id`` plays with these options, built without a simulator, and the
    environment's other options, every one with its value.

    Raises:
        ValueError: ``env_id`` is not registered, or an option has a bad value.
        TypeError: an option the environment does not take.
    """
    task_class = env_entry(env_id).task
    options = env_options(env_id, env_kwargs)
    # The environment hands its task the options named as the task's keyword arguments.
    own = inspect.signature(task_class).parameters
    task = task_class(**{name: options.pop(name) for name in own if name in options})
    return task, options


def check_env_options(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> CheckedOptions:
    """Check options as the environment does, building nothing (no simulator, no
    environment): their names, types and ranges, the task's and the shared ones.

    Returns:
        The options checked, with the task, and the observation's and action's sizes.

    Raises:
        ValueError: ``env_id`` is not registered, or an option has a bad value.
        TypeError: an option the environment does not take.
    """
    check_env_id(env_id)
    task, options = make_task(env_id, env_kwargs)
    return cast("type[FoosballEnv]", env_class(env_id)).check_options(task, **options)


def observation_size(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> int:
    """The size of the observations of ``env_id`` with these options (gymnasium.make's own
    keywords among them are left out), building nothing where ``env_id`` is one of
    :data:`ENVS`; another registered environment is made to tell.

    Raises:
        ValueError: ``env_id`` is not registered, or an option has a bad value.
        TypeError: an option the environment does not take.
    """
    if env_id not in _BY_ID:
        env = gym.make(env_id, **(env_kwargs or {}))
        shape = env.observation_space.shape
        env.close()
        return int(np.prod(shape or ()))
    own = set(inspect.signature(gym.make).parameters)
    options = {k: v for k, v in (env_kwargs or {}).items() if k not in own}
    return check_env_options(env_id, options).observation_size


def interface_of(task: Task, env_kwargs: Mapping[str, Any]) -> TaskInterface:
    """The task's observation builder and action mapping for the environment's options."""
    options = observation_options(
        bool(task.layout.opponent),
        **{k: env_kwargs[k] for k in OBSERVATION_OPTIONS if k in env_kwargs},
    )
    return TaskInterface.create(task.layout, task.extras, options)


def task_interface(env_id: str, env_kwargs: Mapping[str, Any] | None = None) -> TaskInterface:
    """The interface of a registered environment with these options, built without a simulator:
    what the real table needs to run a policy trained on the task."""
    return interface_of(*make_task(env_id, env_kwargs))


def scripted_policy(
    env_id: str,
    env_kwargs: Mapping[str, Any] | None = None,
    on_table: bool = False,
    level: int | None = None,
) -> Any:
    """The scripted baseline of the environment ``env_id`` with options ``env_kwargs``, for
    the environment's state or, with ``on_table``, for a table's camera and filter (as with
    ``estimated_state=True``); ``level``: rung ``level`` of its scripted ladder instead
    (:mod:`foosball_gym.policies.ladder`).

    Raises:
        ValueError: ``env_id`` is not registered, an option has a bad value, or the
            environment has no such level.
        TypeError: an option the environment does not take.
    """
    return scripted_for(check_env_options(env_id, env_kwargs), on_table, level)


def scripted_for(checked: CheckedOptions, on_table: bool = False, level: int | None = None) -> Any:
    """:func:`scripted_policy` for options already checked (:func:`check_env_options`), so that
    a caller that has them resolves nothing again.

    Raises:
        ValueError: the environment has no such level, or reads its slide actions around the
            ball (``slide_around_ball``), which no scripted policy plays.
    """
    from foosball_gym.envs.options import check_scripted_slides

    check_scripted_slides(checked.interface.slide_around_ball)
    precise = not (on_table or checked.values.estimated_state)
    names = list(checked.interface.builder.names)
    return checked.task.scripted_level(level, names, precise)


def describe_envs(env_id: str | None = None) -> str:
    """Every registered environment (or only ``env_id``) with its spaces, and each option with
    its default, the values it takes where they are few, and the first sentence of its
    description.

    Raises:
        ValueError: ``env_id`` is not registered; the message names the ids that are.
    """
    from foosball_gym.envs.options import summary, type_name

    lines = []
    for entry in ENVS if env_id is None else [env_entry(env_id)]:
        checked = check_env_options(entry.id)
        cls = cast("type[FoosballEnv]", env_class(entry.id))
        lines.append(
            f"{entry.id}  ({entry.max_episode_steps} steps, action ({checked.action_size},)"
            f", observation ({checked.observation_size},))"
        )
        lines.append("    " + (cls.__doc__ or "").strip().splitlines()[0])
        if entry.task.ladder:
            levels = ", ".join(f"{i} {level.name}" for i, level in enumerate(entry.task.ladder))
            lines.append(f"    scripted ladder (scripted:N; scripted is the top): {levels}")
        grid, docs = cls.option_grid(), cls.argument_docs()
        for name, p in inspect.signature(cls).parameters.items():
            values = grid.get(name)
            allowed = f"  one of {', '.join(map(repr, values))}" if values else ""
            lines.append(f"    {name}: {type_name(p.annotation)} = {p.default!r}{allowed}")
            lines += textwrap.wrap(
                summary(docs[name]), 100, initial_indent=" " * 8, subsequent_indent=" " * 8
            )
        lines.append("")
    return "\n".join(lines)
