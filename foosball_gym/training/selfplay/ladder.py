"""The scripted ladder as self-play's anchors: which rungs a run's scripted games meet, and,
with ``selfplay_ladder_steps``, a curriculum that lets them in one at a time, in the order the
run lists them, so that a learner from nothing meets the team that stands still before the one
that kicks (docs/self-play.md)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from foosball_gym.training.selfplay.opponents import find_selfplay_env

if TYPE_CHECKING:
    from foosball_gym.training.config import TrainConfig


def check_levels(config: TrainConfig, scripted_level: Callable[[int], object]) -> None:
    """Check ``config``'s selfplay_scripted_levels against ``scripted_level``, which makes the
    scripted team of a rung of the task's ladder or raises ValueError, and its
    selfplay_ladder_steps; the levels are stored as a tuple."""
    levels = config.selfplay_scripted_levels
    if isinstance(levels, str | bytes) or not all(
        isinstance(n, int) and not isinstance(n, bool) for n in levels
    ):
        raise ValueError(
            "selfplay_scripted_levels must be a list of the ladder's rung numbers, e.g. "
            f"[1, 2, 3], got {levels!r}"
        )
    if not config.self_play or not config.selfplay_scripted_share:
        raise ValueError(
            "selfplay_scripted_levels says which scripted teams the scripted share of "
            "self-play's games meets: it needs self-play and selfplay_scripted_share above 0"
        )
    for level in levels:
        try:
            scripted_level(level)
        except ValueError as e:
            raise ValueError(f"selfplay_scripted_levels: {e}") from None
    config.selfplay_scripted_levels = tuple(levels)


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


class LadderCurriculum(BaseCallback):
    """Before each rollout, lets the training environments' scripted games meet as many of
    the listed rungs as the run's step count allows (so a resumed run goes on where it was),
    and records how many under ``selfplay/ladder_rungs`` in TensorBoard."""

    def __init__(self, ladder_steps: int, n_levels: int) -> None:
        super().__init__()
        self.ladder_steps = ladder_steps
        self.n_levels = n_levels

    def apply(self, venv: VecEnv, steps_done: int) -> int:
        """Let ``venv``'s scripted games meet the rungs of a run ``steps_done`` steps in;
        returns how many."""
        rungs = rungs_in_play(steps_done, self.ladder_steps, self.n_levels)
        find_selfplay_env(venv).anchors_in_play = rungs
        return rungs

    def _on_rollout_start(self) -> None:
        self.logger.record(
            "selfplay/ladder_rungs", self.apply(self.training_env, self.num_timesteps)
        )

    def _on_step(self) -> bool:
        return True
