"""A curriculum over serves: a run's incoming shots start easier and become the task's own.

``TrainConfig.curriculum`` names serve options (``speed_range``, ``serve_x_range``, ...;
Score with obstacles its ``obstacle_share`` and, the ball at rest, its ``shut_lane_share``;
keeper against keeper its ``home_serve_share``) with the values the run starts from; over its
first ``curriculum_steps`` steps each moves in a straight line to the run's own value (its
``env_kwargs``', or the environment's default), and stays there. Needs no simulator: the
values are checked as the environment checks them.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from foosball_gym.registration import check_env_options
from foosball_gym.tasks.base import Task


def run_serves(env_id: str, env_kwargs: Mapping[str, Any], names: list[str]) -> dict[str, Any]:
    """The serve options ``names`` (checked: :func:`check_curriculum`) as the run's environment
    has them: where a curriculum ends."""
    own = _task(env_id, env_kwargs).serve_options()
    return {name: own[name] for name in names}


def check_curriculum(
    env_id: str, env_kwargs: Mapping[str, Any], start: Mapping[str, Any], steps: int
) -> None:
    """Raise ValueError, saying what is allowed, for a curriculum the run cannot follow."""
    if not isinstance(start, Mapping):
        raise ValueError(
            "curriculum must map serve options to the values the run starts from, e.g. "
            f"{{speed_range: [1.0, 3.0]}}, got {start!r}"
        )
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ValueError(f"curriculum_steps must be a whole number, 0 or more, got {steps!r}")
    if bool(start) != (steps > 0):
        raise ValueError(
            "a curriculum needs both its starting serves (curriculum) and the steps over which "
            f"they become the run's (curriculum_steps, at least 1); got {dict(start)!r} over "
            f"{steps} steps"
        )
    if not start:
        return
    task = _task(env_id, env_kwargs)
    own = task.serve_options()
    unknown = sorted(set(start) - set(own))
    if unknown:
        raise ValueError(
            f"curriculum: unknown serve option {unknown[0]!r}; allowed here: {', '.join(own)}"
        )
    try:
        task.set_serves(**start)
    except ValueError as e:
        raise ValueError(f"curriculum: {e}") from None
    for name, first in start.items():
        if _is_pair(own[name]) != _is_pair(first):
            raise ValueError(
                f"curriculum: {name} must be given as the run's is, "
                f"{'a pair (low, high)' if _is_pair(own[name]) else 'a number'}, got {first!r}"
            )


def serves_at(start: Mapping[str, Any], end: Mapping[str, Any], fraction: float) -> dict[str, Any]:
    """The serve options a ``fraction`` (0 to 1) of the way from ``start`` to ``end``."""
    f = min(max(fraction, 0.0), 1.0)

    def between(a: float, b: float) -> float:
        return float(a) + f * (float(b) - float(a))

    values: dict[str, Any] = {}
    for name, first in start.items():
        last = end[name]
        if _is_pair(last):
            values[name] = (between(first[0], last[0]), between(first[1], last[1]))
        else:
            values[name] = between(first, last)
    return values


def _task(env_id: str, env_kwargs: Mapping[str, Any]) -> Task:
    task = check_env_options(env_id, env_kwargs).task
    if not task.serve_options():
        task.set_serves()  # raises, saying which tasks serve shots
    return task


def _is_pair(value: Any) -> bool:
    return isinstance(value, list | tuple)
