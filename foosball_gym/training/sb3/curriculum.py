"""The callback that moves a run's serves along its curriculum
(:mod:`foosball_gym.training.curriculum`)."""

from __future__ import annotations

from typing import Any

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv

from foosball_gym.training.config import TrainConfig
from foosball_gym.training.curriculum import run_serves, serves_at


class ServeCurriculum(BaseCallback):
    """Before each rollout, sets the training environments' serves to where the curriculum
    stands at the run's step count (so a resumed run goes on where it was), and records them
    in TensorBoard under ``curriculum/``. The evaluations play the run's own serves."""

    def __init__(self, config: TrainConfig) -> None:
        super().__init__()
        self.start = dict(config.curriculum)
        self.end = run_serves(config.env_id, config.env_kwargs, list(self.start))
        self.steps = config.curriculum_steps
        self._done = False

    def apply(self, venv: VecEnv, steps_done: int) -> dict[str, Any]:
        """Set ``venv``'s serves for a run ``steps_done`` steps in; returns them."""
        values = serves_at(self.start, self.end, steps_done / self.steps)
        venv.env_method("set_serves", **values)
        self._done = steps_done >= self.steps
        return values

    def _on_rollout_start(self) -> None:
        if self._done:
            return
        values = self.apply(self.training_env, self.num_timesteps)
        for name, value in values.items():
            pair = isinstance(value, tuple)
            parts = {"_low": value[0], "_high": value[1]} if pair else {"": value}
            for suffix, v in parts.items():
                self.logger.record(f"curriculum/{name}{suffix}", v)

    def _on_step(self) -> bool:
        return True
