"""What the two games share: single serves or a match of many, and a match's rules.

A game is one serve by default: it ends at a goal, with the ball off the table, or with a dead
ball. A *match* (``continuous=True``) serves again after each of these and keeps the score:
until its time is up (``match_seconds``, or the registered time limit) or, first to N, until a
side has scored ``first_to`` goals. In either, a ball at rest that no figurine in play can
reach is dead after ``dead_ball_steps`` (the table's rules serve it again), and any ball lying
still for the environment's ``stagnation_steps`` is too.
"""

from __future__ import annotations

import math
from typing import Any

from foosball_gym.policy_io.observations import check_flag
from foosball_gym.tasks.base import Task


def _whole(name: str, value: Any) -> int:
    if isinstance(value, bool) or not float(value).is_integer() or value < 0:
        raise ValueError(f"{name} must be a whole number, 0 or more, got {value!r}")
    return int(value)


#: The games' ``dead_ball_steps``: half a second at rest out of reach. A rolling ball slower
#: than 5 cm/s covers at most 2.5 cm in it, less than the gap between two rods' reaches.
DEAD_BALL_STEPS = 30


class GameTask(Task):
    """A game between two sides: one serve, or a match of many.

    Args:
        continuous: play a match of many serves instead of one.
        first_to: in a match, end it as soon as a side has this many goals (0: play on until
            time is up).
        match_seconds: in a match, its length in seconds of play (None: until the time limit).
        dead_ball_steps: a ball at rest out of every figurine's reach for this many control
            steps is dead (0: never).
    """

    def __init__(
        self,
        *,
        continuous: bool = False,
        first_to: int = 0,
        match_seconds: float | None = None,
        dead_ball_steps: int = 0,
    ) -> None:
        self.continuous = check_flag("continuous", continuous)
        self.continues_after_goal = self.continuous
        try:
            self.first_to = _whole("first_to", first_to)
            self.dead_ball_steps = _whole("dead_ball_steps", dead_ball_steps)
        except (TypeError, ValueError) as err:
            raise ValueError(str(err)) from None
        if match_seconds is not None:
            try:
                match_seconds = float(match_seconds)
            except (TypeError, ValueError):
                match_seconds = math.nan
            if not 0.0 < match_seconds < math.inf:
                raise ValueError(
                    f"match_seconds must be a number of seconds above 0, or None, "
                    f"got {match_seconds!r}"
                )
        self.match_seconds = match_seconds
        for name, value in (("first_to", self.first_to), ("match_seconds", match_seconds)):
            if value and not self.continuous:
                raise ValueError(
                    f"{name} sets a rule of a match of many serves: it needs continuous=True"
                )

    def success(self, goals_for: int, goals_against: int) -> bool:
        if self.continuous:
            return goals_for > goals_against
        return goals_for > 0

    def match_over(self, goals_for: int, goals_against: int) -> bool:
        return bool(self.first_to) and max(goals_for, goals_against) >= self.first_to

    def match_steps(self, control_hz: int) -> int | None:
        if self.match_seconds is None:
            return None
        return max(1, round(self.match_seconds * control_hz))
