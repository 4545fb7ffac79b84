"""Clips of the policy while it trains: ``videos/step_<timesteps>.mp4`` (``video_every``)."""

from __future__ import annotations

import contextlib
import random
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.callbacks import BaseCallback

from foosball_gym.evaluation import evaluate
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.loading.sb3_snapshot import PolicySnapshot
from foosball_gym.training.run_dir.files import VIDEO_DIR
from foosball_gym.training.sb3.callbacks import EvalCurveCallback
from foosball_gym.training.signals import Interrupted, SignalStop

# Apart from the evaluations' seeds (1_000_000 on), and the same for every clip of a run, so
# that its clips show the same episodes played better and better.
VIDEO_SEED = 2_000_000
# A clip holds up to 3 episodes, as many as fit in 1200 steps (20 s at 60 Hz), and at least
# one: 3 of Block's, a single match of the two-player games.
VIDEO_MAX_EPISODES = 3
VIDEO_STEPS = 1200
# Every 2nd frame (30 a second at 60 Hz) halves the rendering, most of a clip's cost.
VIDEO_STRIDE = 2


def clip_episodes(env_id: str) -> int:
    """How many episodes a training clip of ``env_id`` holds."""
    max_steps = gym.spec(env_id).max_episode_steps or VIDEO_STEPS
    return max(1, min(VIDEO_MAX_EPISODES, VIDEO_STEPS // max_steps))


@contextmanager
def _global_rng_kept() -> Iterator[None]:
    """Restore Python's, NumPy's and PyTorch's global generators on leaving.

    Training draws from them (PPO's actions and minibatches, SAC's noise); what runs in
    between, such as building a policy snapshot, must leave them as it found them, or a run
    would learn differently for having recorded a clip.
    """
    py, np_state, th_state = random.getstate(), np.random.get_state(), th.get_rng_state()
    try:
        yield
    finally:
        random.setstate(py)
        np.random.set_state(np_state)
        th.set_rng_state(th_state)


class VideoCallback(BaseCallback):
    """Every ``config.video_every`` steps write ``videos/step_NNNNNNNNN.mp4``: the current
    policy playing :func:`clip_episodes` seeded episodes, deterministically.

    The clip plays on an env of its own, seeded from :data:`VIDEO_SEED`, with the observation
    normalisation the policy sees in training, against the env's scripted opponent in
    two-player tasks (as the evaluations in eval.csv do), not the self-play opponent of the
    moment. It changes nothing training depends on: the global generators are restored after
    it, and its time is left out of eval.csv's ``wall_seconds``.
    """

    def __init__(
        self,
        config: TrainConfig,
        out: Path,
        curve: EvalCurveCallback | None = None,
        stop: SignalStop | None = None,
    ) -> None:
        super().__init__()
        self.stop = stop
        if config.video_every is None:
            raise ValueError("VideoCallback needs config.video_every")
        self.config = config
        self.every = config.video_every
        self.dir = out / VIDEO_DIR
        self.curve = curve
        self._next = 0

    def _on_training_start(self) -> None:
        self._next = (self.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.every
            try:
                self.record()
            except Interrupted:
                return False  # a signal, during the clip: the run stops, without it
        return True

    def record(self) -> Path:
        """Write the clip of the policy now; its path. A signal during it (with ``stop``)
        raises :class:`~foosball_gym.training.signals.Interrupted`, the clip unwritten."""
        start = time.perf_counter()
        self.dir.mkdir(parents=True, exist_ok=True)
        path = self.dir / f"step_{self.num_timesteps:09d}.mp4"
        # The writer picks the container by the suffix: the temporary name keeps it.
        tmp = path.with_name(path.stem + ".tmp.mp4")
        episodes = clip_episodes(self.config.env_id)
        interruptible = self.stop.interruptible() if self.stop else contextlib.nullcontext()
        try:
            with _global_rng_kept(), interruptible:
                evaluate(
                    PolicySnapshot.of_model(self.model),
                    self.config.env_id,
                    self.config.env_kwargs,
                    episodes=episodes,
                    seed=VIDEO_SEED,
                    video=tmp,
                    video_episodes=episodes,
                    video_stride=VIDEO_STRIDE,
                )
            tmp.replace(path)
        finally:
            tmp.unlink(missing_ok=True)
        if self.curve is not None:
            self.curve.pause_clock(time.perf_counter() - start)
        return path
