"""The SB3 callback that climbs the scripted ladder during a run (``selfplay_ladder_steps``)."""

from __future__ import annotations

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from foosball_gym.training.selfplay.ladder import rungs_in_play
from foosball_gym.training.selfplay.opponents import find_selfplay_env


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
