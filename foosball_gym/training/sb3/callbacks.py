"""The callbacks every Stable-Baselines3 run has: its evaluation curve and best model, its
checkpoints, its stop on a signal, and its progress."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from foosball_gym.evaluation import evaluate
from foosball_gym.progress import Progress
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.run_dir.best import BestModel
from foosball_gym.training.run_dir.curve import EVAL_SEED, EvalCurve, eval_row
from foosball_gym.training.run_dir.files import CHECKPOINT_DIR, MODEL_FILE, write_latest
from foosball_gym.training.run_dir.storage import save_model
from foosball_gym.training.sb3.numpy_snapshot import NumpySnapshot
from foosball_gym.training.sb3.replay import drop_old_replays, write_run_replay
from foosball_gym.training.signals import Interrupted, SignalStop


class EvalCurveCallback(BaseCallback):
    """Every ``eval_freq`` steps: evaluate on seeded episodes, add the row to eval.csv and its
    plot, and keep the best model so far in ``best/``.

    With ``stop``, the run's :class:`StopOnSignal`, a signal ends an evaluation where it lands
    (no row is written) and the run with it; the run resumed, the evaluation it missed is the
    first thing it does.
    """

    def __init__(
        self,
        config: TrainConfig,
        out: Path,
        wall_offset: float = 0.0,
        stop: SignalStop | None = None,
    ) -> None:
        super().__init__()
        self.config = config
        self.curve = EvalCurve(out, config.env_id)
        self.best = BestModel(out)
        self.wall_offset = wall_offset
        self.stop = stop
        self._start = time.perf_counter()
        self._next = 0
        # The success rate of the last evaluation, for the progress bar: a resumed run's is
        # in the curve it goes on from (None: none yet).
        rows = self.curve.rows()
        self.last_success: float | None = rows[-1]["success_rate"] if rows else None
        self.reached: dict[str, Any] | None = None
        self._going_on = True

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()
        every = self.config.eval_freq
        self._next = (self.num_timesteps // every + 1) * every
        rows = self.curve.rows()
        last = rows[-1]["timesteps"] if rows else 0
        if self.num_timesteps and (self.num_timesteps // every) * every > last:
            # Due before the checkpoint this run goes on from, and never written (a signal
            # stopped it half-way): the model is the checkpoint's still.
            self._going_on = self.run_eval()

    def _on_step(self) -> bool:
        if not self._going_on or self.num_timesteps < self._next:
            return self._going_on
        self._next = (self.num_timesteps // self.config.eval_freq + 1) * self.config.eval_freq
        return self.run_eval()

    def pause_clock(self, seconds: float) -> None:
        """Leave ``seconds`` out of the curve's ``wall_seconds``: time spent on what is no
        part of learning (recording clips), so that runs compare on their training time."""
        self._start += seconds

    def run_eval(self) -> bool:
        try:
            with self.stop.interruptible() if self.stop else contextlib.nullcontext():
                res = evaluate(
                    NumpySnapshot.of_model(self.model),
                    self.config.env_id,
                    self.config.env_kwargs,
                    episodes=self.config.eval_episodes,
                    seed=EVAL_SEED,
                )
        except Interrupted:
            return False
        wall = self.wall_offset + time.perf_counter() - self._start
        row = eval_row(res, self.num_timesteps, wall)
        self.curve.append(row)
        self.last_success = res.success_rate
        self.logger.record("eval/success_rate", res.success_rate)
        self.logger.record("eval/mean_reward", res.mean_reward)
        self.best.offer(row, self._save_best)
        target = self.config.target_success
        if target is not None and res.success_rate >= target:
            self.reached = row
            return False
        return True

    def _save_best(self, best: Path) -> None:
        save_model(self.model, best / MODEL_FILE)


def rollout_steps(model: Any) -> int:
    """The steps ``model.learn`` takes at a time, over all its environments: an on-policy
    algorithm's rollout (``n_steps`` of each), else one step of each."""
    return int(getattr(model, "n_steps", 1) or 1) * int(model.n_envs)


def steps_run(model: Any, done: int, remaining: int) -> int:
    """The step count ``model.learn(remaining)`` ends at, from ``done``: ``remaining``
    rounded up to whole rollouts, as SB3 runs them."""
    rollout = rollout_steps(model)
    return done + -(-remaining // rollout) * rollout


class ProgressCallback(BaseCallback):
    """The run's steps on standard error (:class:`~foosball_gym.progress.Progress`), up to
    ``total`` (what the run ends at, whole rollouts), with the success rate of the last
    evaluation of ``evaluations``."""

    def __init__(self, total: int, evaluations: EvalCurveCallback) -> None:
        super().__init__()
        self.total = total
        self.evaluations = evaluations
        self.count: Progress | None = None
        self._seen = 0
        self._shown: float | None = None

    def _on_training_start(self) -> None:
        self._seen = self.num_timesteps
        self.count = Progress(self.total, "train", "steps", initial=self._seen)

    def _on_step(self) -> bool:
        assert self.count is not None
        last = self.evaluations.last_success
        if last is not None and last != self._shown:
            self._shown = last
            self.count.set_note(f"last evaluation {100 * last:.1f} %")
        self.count.update(self.num_timesteps - self._seen)
        self._seen = self.num_timesteps
        return True

    def _on_training_end(self) -> None:
        if self.count is not None:
            self.count.close()


class CheckpointCallback(BaseCallback):
    """Every ``every`` steps write the model with its normalisation, then a pointer to it,
    each atomically."""

    def __init__(self, out: Path, every: int) -> None:
        super().__init__()
        self.out = out
        self.dir = out / CHECKPOINT_DIR
        self.every = every
        self._next = 0
        self._wait_for_rollout = False
        self._due = False

    def _on_training_start(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        self._next = (self.num_timesteps // self.every + 1) * self.every
        # SB3 stores a step's transitions after its callbacks: an off-policy model's checkpoint
        # waits for the end of the rollout, so that its buffer holds every step it counts.
        self._wait_for_rollout = getattr(self.model, "replay_buffer", None) is not None
        self._due = False

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.every
            if self._wait_for_rollout:
                self._due = True
            else:
                self.write()
        return True

    def _on_rollout_end(self) -> None:
        if self._due:
            self._due = False
            self.write()

    def write(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        name = f"model_{self.num_timesteps:010d}"
        save_model(self.model, self.dir / f"{name}.zip")
        pointer: dict[str, Any] = {"model": f"{name}.zip", "timesteps": int(self.num_timesteps)}
        replay = write_run_replay(self.model, self.out, self.num_timesteps)
        if replay is not None:
            pointer["replay"] = replay
        write_latest(self.out, pointer)
        if replay is not None:
            drop_old_replays(self.out, keep=replay)


class StopOnSignal(SignalStop, BaseCallback):
    """SB3's face of :class:`SignalStop`: ends ``learn`` at the next step after a signal."""

    def _on_step(self) -> bool:
        return self.signum is None
