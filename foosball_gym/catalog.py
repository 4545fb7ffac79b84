"""The registered environments: their ids checked, their options listed, their scripted
baselines built. What ``foosball envs`` prints and what eval and play fall back on."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from foosball_gym.registration import ENV_IDS


def check_env_id(env_id: str) -> None:
    """Raise ValueError naming the registered ids where ``env_id`` is not one of them."""
    if env_id not in gym.registry:
        known = ", ".join(ENV_IDS)
        raise ValueError(f"unknown environment {env_id!r}; registered: {known}")


def scripted_policy(
    env_id: str, env_kwargs: dict[str, Any] | None = None, on_table: bool = False
) -> Any:
    """The scripted baseline of the environment ``env_id`` with options ``env_kwargs``, for
    the environment's state or, with ``on_table``, for a table's camera and filter (as with
    ``estimated_state=True``).

    Raises:
        ValueError: ``env_id`` is not registered, or an option has a bad value.
    """
    from foosball_gym.tasks import interface_of, make_task

    check_env_id(env_id)
    task, options = make_task(env_id, env_kwargs)
    precise = not (on_table or options.get("estimated_state", False))
    return task.scripted_policy(interface_of(task, options).builder.names, precise)


def describe_envs() -> str:
    """Every registered environment with its spaces and its options' defaults and values."""
    lines = []
    for env_id in ENV_IDS:
        spec = gym.spec(env_id)
        env = gym.make(env_id)
        cls = type(env.unwrapped)
        lines.append(
            f"{env_id}  ({spec.max_episode_steps} steps, action {env.action_space.shape}"
            f", observation {env.observation_space.shape})"
        )
        first = (cls.__doc__ or "").strip().splitlines()[0]
        lines.append(f"    {first}")
        for name, default in cls.option_defaults().items():
            if name.startswith("opponent") and not env.unwrapped.layout.opponent:
                continue
            values = cls.option_grid().get(name)
            allowed = f"  one of {', '.join(map(repr, values))}" if values else ""
            lines.append(f"    {name} = {default!r}{allowed}")
        env.close()
        lines.append("")
    return "\n".join(lines)
