"""The scripted ladder as self-play's anchors: which rungs a run's scripted games meet, and,
with ``selfplay_ladder_steps``, how many of them are let in so far, one at a time in the order
the run lists them, so that a learner from nothing meets the team that stands still before the
one that kicks (docs/self-play.md). The checks here need neither SB3 nor the run's
configuration class, which calls them."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any


def check_levels(
    levels: Any, self_play: bool, scripted_share: float, scripted_level: Callable[[int], object]
) -> tuple[int, ...]:
    """Check a run's selfplay_scripted_levels against ``scripted_level``, which makes the
    scripted team of a rung of the task's ladder or raises ValueError; returns them as a
    tuple."""
    if isinstance(levels, str | bytes) or not all(
        isinstance(n, int) and not isinstance(n, bool) for n in levels
    ):
        raise ValueError(
            "selfplay_scripted_levels must be a list of the ladder's rung numbers, e.g. "
            f"[1, 2, 3], got {levels!r}"
        )
    if not self_play or not scripted_share:
        raise ValueError(
            "selfplay_scripted_levels says which scripted teams the scripted share of "
            "self-play's games meets: it needs self-play and selfplay_scripted_share above 0"
        )
    for level in levels:
        try:
            scripted_level(level)
        except ValueError as e:
            raise ValueError(f"selfplay_scripted_levels: {e}") from None
    return tuple(levels)


def check_ladder_steps(steps: Any, levels: Sequence[int]) -> None:
    """Refuse a selfplay_ladder_steps that is not a whole number, or that has no rungs to let
    in one at a time."""
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
        raise ValueError(
            f"selfplay_ladder_steps must be a whole number of steps (0: every rung from the "
            f"start), got {steps!r}"
        )
    if steps and len(levels) < 2:
        raise ValueError(
            "selfplay_ladder_steps lets the rungs of selfplay_scripted_levels in one at a time: "
            f"it needs at least two of them, e.g. [0, 1, 2], got {list(levels)!r}"
        )


def rungs_in_play(steps_done: int, ladder_steps: int, n_levels: int) -> int:
    """How many of a run's listed rungs its scripted games meet ``steps_done`` steps in: the
    first from the start, one more every ``ladder_steps`` (0: all of them)."""
    if not ladder_steps:
        return n_levels
    return min(n_levels, 1 + steps_done // ladder_steps)
