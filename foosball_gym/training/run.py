"""A training run: environments, model, callbacks, checkpoints, resume.

Its configuration is :class:`~foosball_gym.training.config.TrainConfig`; the files it writes
are listed in :mod:`foosball_gym.training.files`.
"""

from __future__ import annotations

import csv
import json
import random
import shutil
import signal
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

import foosball_gym.registration  # noqa: F401  (the package registers the ids)
from foosball_gym.evaluation import evaluate
from foosball_gym.table import PHYSICS_REVISION
from foosball_gym.training.config import (
    ALGORITHMS,
    VEC_ENV_KINDS,
    PhysicsMismatchWarning,
    TrainConfig,
    physics_mismatch,
)
from foosball_gym.training.curve import plot_curve, read_curve
from foosball_gym.training.files import (
    BEST_DIR,
    CHECKPOINT_DIR,
    CONFIG_FILE,
    LATEST_FILE,
    LEGACY_NORM_FILE,
    MODEL_FILE,
    NORM_FILE,
    atomic_write_text,
    has_checkpoint,
)
from foosball_gym.training.pretrain import clone, collect
from foosball_gym.training.selfplay import OpponentActionWrapper, SelfPlayCallback, SelfPlayVecEnv
from foosball_gym.training.selfplay_gate import ReplacementGate
from foosball_gym.training.signals import SignalStop
from foosball_gym.training.snapshot import PolicySnapshot
from foosball_gym.training.storage import read_model_zip, read_norm, save_model
from foosball_gym.training.teacher import TeacherCallback

ALGOS = dict(zip(ALGORITHMS, (PPO, SAC), strict=True))


def _ignoring_sigint(env_fn: Callable[[], Any]) -> Callable[[], Any]:
    def make() -> Any:
        # Ctrl-C reaches every process of the terminal's group; the main process alone stops
        # the run, after writing a checkpoint, and a worker gone first would break its last
        # steps.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        # This function reaches the worker by value, so nothing has registered the ids there.
        import foosball_gym.registration  # noqa: F401, F811

        return env_fn()

    return make


def subproc_vec_env(env_fns: list[Callable[[], Any]], **kwargs: Any) -> SubprocVecEnv:
    """``SubprocVecEnv`` whose workers ignore SIGINT."""
    return SubprocVecEnv([_ignoring_sigint(fn) for fn in env_fns], **kwargs)


VEC_ENVS = dict(zip(VEC_ENV_KINDS, (DummyVecEnv, subproc_vec_env), strict=True))


def make_env(config: TrainConfig, seed_offset: int = 0) -> Any:
    """The vectorised training envs (with self-play and normalisation wrappers as configured)."""
    wrapper = OpponentActionWrapper if config.self_play else None
    venv = make_vec_env(
        config.env_id,
        n_envs=config.n_envs,
        seed=config.seed + seed_offset,
        env_kwargs=config.env_kwargs,
        wrapper_class=wrapper,
        vec_env_cls=VEC_ENVS[config.vec_env],
    )
    if config.self_play:
        # The first opponent is replaced by a snapshot of the learner as training starts.
        n = venv.action_space.shape[0] // 2
        anchor = None
        if config.selfplay_scripted_share:
            anchor = venv.env_method("scripted_opponent", indices=[0])[0]
        venv = SelfPlayVecEnv(
            venv,
            lambda obs: np.zeros((len(obs), n), np.float32),
            config.seed,
            anchor=anchor,
            anchor_share=config.selfplay_scripted_share,
        )
    if config.normalize or config.normalize_reward:
        venv = VecNormalize(
            venv, norm_obs=config.normalize, norm_reward=config.normalize_reward, gamma=config.gamma
        )
    return venv


def build_model(config: TrainConfig, venv: Any, tb_dir: Path | None) -> Any:
    policy_kwargs = {"net_arch": list(config.net_arch)}
    lr = config.learning_rate
    common = {
        # SB3 calls a schedule with the progress remaining, from 1 down to 0.
        "learning_rate": (lambda remaining: lr * remaining)
        if config.lr_schedule == "linear"
        else lr,
        "gamma": config.gamma,
        "seed": config.seed,
        "device": "cpu",
        "verbose": 0,
        "tensorboard_log": None if tb_dir is None else str(tb_dir),
    }
    if config.algo == "ppo":
        policy_kwargs["log_std_init"] = config.log_std_init
        return PPO(
            "MlpPolicy",
            venv,
            n_steps=config.n_steps,
            batch_size=config.batch_size,
            n_epochs=config.n_epochs,
            gae_lambda=config.gae_lambda,
            clip_range=config.clip_range,
            target_kl=config.target_kl,
            policy_kwargs=policy_kwargs,
            **common,
        )
    return SAC(
        "MlpPolicy", venv, batch_size=config.batch_size, policy_kwargs=policy_kwargs, **common
    )


class EvalCurveCallback(BaseCallback):
    """Every ``eval_freq`` steps: evaluate on seeded episodes, append to eval.csv, plot, and
    keep the best model so far in ``best/`` (PPO's success rate can fall back after a peak)."""

    FIELDS = (
        "timesteps",
        "wall_seconds",
        "success_rate",
        "ci_low",
        "ci_high",
        "mean_reward",
        "mean_length",
        "goals_for",
        "goals_against",
    )

    def __init__(self, config: TrainConfig, out: Path, wall_offset: float = 0.0) -> None:
        super().__init__()
        self.config = config
        self.csv = out / "eval.csv"
        self.png = out / "eval.png"
        self.best_dir = out / BEST_DIR
        best_file = self.best_dir / "best.json"
        self.best = (
            json.loads(best_file.read_text())["success_rate"] if best_file.exists() else -1.0
        )
        self.wall_offset = wall_offset
        self._start = time.perf_counter()
        self._next = 0
        self.reached: dict[str, float] | None = None

    def _on_training_start(self) -> None:
        self._start = time.perf_counter()
        self._next = (self.num_timesteps // self.config.eval_freq + 1) * self.config.eval_freq

    def _on_step(self) -> bool:
        if self.num_timesteps < self._next:
            return True
        self._next += self.config.eval_freq
        return self.run_eval()

    def pause_clock(self, seconds: float) -> None:
        """Leave ``seconds`` out of the curve's ``wall_seconds``: time spent on what is no
        part of learning (recording clips), so that runs compare on their training time."""
        self._start += seconds

    def run_eval(self) -> bool:
        policy = PolicySnapshot.of_model(self.model)
        res = evaluate(
            policy,
            self.config.env_id,
            self.config.env_kwargs,
            episodes=self.config.eval_episodes,
            seed=1_000_000,
        )
        row = {
            "timesteps": self.num_timesteps,
            "wall_seconds": round(self.wall_offset + time.perf_counter() - self._start, 2),
            "success_rate": res.success_rate,
            "ci_low": round(res.ci_low, 4),
            "ci_high": round(res.ci_high, 4),
            "mean_reward": round(res.mean_reward, 3),
            "mean_length": res.mean_length,
            "goals_for": res.goals_for,
            "goals_against": res.goals_against,
        }
        new = not self.csv.exists()
        with self.csv.open("a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=self.FIELDS)
            if new:
                writer.writeheader()
            writer.writerow(row)
        self.logger.record("eval/success_rate", res.success_rate)
        self.logger.record("eval/mean_reward", res.mean_reward)
        plot_curve(self.csv, self.png, self.config.env_id)
        if res.success_rate >= self.best:
            self.best = res.success_rate
            self.best_dir.mkdir(exist_ok=True)
            save_model(self.model, self.best_dir / MODEL_FILE, self.best_dir / NORM_FILE)
            atomic_write_text(self.best_dir / "best.json", json.dumps(row))
        target = self.config.target_success
        if target is not None and res.success_rate >= target:
            self.reached = row
            return False
        return True


VIDEO_DIR = "videos"
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
        self, config: TrainConfig, out: Path, curve: EvalCurveCallback | None = None
    ) -> None:
        super().__init__()
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
            self.record()
        return True

    def record(self) -> Path:
        """Write the clip of the policy now; its path."""
        start = time.perf_counter()
        self.dir.mkdir(parents=True, exist_ok=True)
        path = self.dir / f"step_{self.num_timesteps:09d}.mp4"
        # The writer picks the container by the suffix: the temporary name keeps it.
        tmp = path.with_name(path.stem + ".tmp.mp4")
        episodes = clip_episodes(self.config.env_id)
        with _global_rng_kept():
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
        if self.curve is not None:
            self.curve.pause_clock(time.perf_counter() - start)
        return path


class CheckpointCallback(BaseCallback):
    """Every ``every`` steps write model, normalisation and a pointer to them, atomically."""

    def __init__(self, out: Path, every: int) -> None:
        super().__init__()
        self.dir = out / CHECKPOINT_DIR
        self.every = every
        self._next = 0

    def _on_training_start(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        self._next = (self.num_timesteps // self.every + 1) * self.every

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.every
            self.write()
        return True

    def write(self) -> None:
        self.dir.mkdir(parents=True, exist_ok=True)
        name = f"model_{self.num_timesteps:010d}"
        save_model(self.model, self.dir / f"{name}.zip", self.dir / f"{name}_{NORM_FILE}")
        pointer = {"model": f"{name}.zip", "timesteps": int(self.num_timesteps)}
        if self.model.get_vec_normalize_env() is not None:
            pointer["vecnormalize"] = f"{name}_{NORM_FILE}"
        atomic_write_text(self.dir / LATEST_FILE, json.dumps(pointer))


class StopOnSignal(SignalStop, BaseCallback):
    """SB3's face of :class:`SignalStop`: ends ``learn`` at the next step after a signal."""

    def _on_step(self) -> bool:
        return self.signum is None


@dataclass
class TrainResult:
    """What a call of :func:`train` did.

    ``signal`` is the number of the signal (SIGINT, SIGTERM) that stopped the run before its
    budget, after a checkpoint was written; None where it ran to the end.
    """

    out: Path
    timesteps: int
    seconds: float
    reached: dict[str, float] | None
    signal: int | None = None


# What a start that failed may leave in a run directory without a checkpoint; a new start
# clears it so that its curve and best model are its own.
_STALE = ("eval.csv", "eval.png", "pretrain.json", BEST_DIR, "selfplay", VIDEO_DIR)


def _extended(config: TrainConfig, timesteps: int, out: Path) -> TrainConfig:
    """``config`` with its run lengthened to ``timesteps`` (refused where that cannot be)."""
    if timesteps <= config.timesteps:
        raise ValueError(
            f"the run in {out} trains {config.timesteps} steps; a resume can only extend it, "
            f"not to {timesteps}"
        )
    if config.lr_schedule != "constant":
        raise ValueError(
            f"the run in {out} decays its learning rate to 0 over {config.timesteps} steps "
            f"(lr_schedule {config.lr_schedule}); a longer run would start the decay over: "
            "resume it as it is, or train a new run"
        )
    config.timesteps = timesteps
    return config


def _record_extension(config: TrainConfig, out: Path) -> None:
    """Write a checked extension into ``config.json``, the rest of the file kept."""
    data = json.loads((out / CONFIG_FILE).read_text())
    data["timesteps"] = config.timesteps
    atomic_write_text(out / CONFIG_FILE, json.dumps(data, indent=2))


def train(
    config: TrainConfig,
    out: str | Path,
    progress_bar: bool = False,
    resume: bool = False,
    callbacks: list[BaseCallback] | None = None,
    timesteps: int | None = None,
) -> TrainResult:
    """Train (or, with ``resume``, continue) the run in directory ``out``.

    Everything is checked, the envs and the model built, before ``config.json`` is written,
    so a start that fails leaves no run behind. A directory with a ``config.json`` but no
    checkpoint (a start stopped before its first one) is no run either: a new one may start
    there, and ``resume`` starts it over from its configuration.

    SIGINT (Ctrl-C) or SIGTERM during training end it at the next step with a checkpoint
    written; the result's ``signal`` says which arrived.

    Args:
        config: the run's configuration (ignored with ``resume``: the run's own is read).
        out: the run directory.
        progress_bar: show SB3's progress bar.
        resume: continue from the last checkpoint in ``out`` (or its final model).
        callbacks: extra SB3 callbacks, run after the run's own.
        timesteps: with ``resume``, train on to this many steps in all, past the run's own
            ``timesteps`` (written into its ``config.json``), so that a long run can go on
            over several sittings.
    """
    out = Path(out)
    if timesteps is not None and not resume:
        raise ValueError("timesteps extends a resumed run; a new run takes config.timesteps")
    if resume:
        config = TrainConfig.load(out / CONFIG_FILE)
        if timesteps is not None:
            config = _extended(config, int(timesteps), out)
        mismatch = physics_mismatch(json.loads((out / CONFIG_FILE).read_text()), f"the run {out}")
        if mismatch:
            # config.json keeps the old revision, so the resumed model goes on warning as well.
            warnings.warn(
                f"{mismatch} Resuming continues it on revision {PHYSICS_REVISION}.",
                PhysicsMismatchWarning,
                stacklevel=2,
            )
    config.check()
    if timesteps is not None:
        # Only once the lengthened configuration is known to be sound.
        _record_extension(config, out)
    th.set_num_threads(config.torch_threads)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} is a file, not a run directory")
    continuing = resume and has_checkpoint(out)
    if not resume and has_checkpoint(out):
        raise ValueError(
            f"{out} already holds a run; use --resume to continue it or choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)

    venv = make_env(config)
    done_steps, wall_offset = 0, 0.0
    try:
        if continuing:
            model, done_steps = _load_checkpoint(config, out, venv)
            if (out / "eval.csv").exists():
                rows = read_curve(out / "eval.csv")
                wall_offset = rows[-1]["wall_seconds"] if rows else 0.0
        else:
            model = build_model(config, venv, out / "tb")
            for name in _STALE:
                stale = out / name
                if stale.is_dir():
                    shutil.rmtree(stale)
                elif stale.exists():
                    stale.unlink()
            config.save(out / CONFIG_FILE)
    except BaseException:
        venv.close()
        raise
    if not continuing and config.pretrain_episodes:
        pretrain_start = time.perf_counter()
        demos = collect(
            config.env_id,
            config.env_kwargs,
            config.pretrain_episodes,
            config.gamma,
            seed=config.seed,
        )
        fit = clone(model, demos, seed=config.seed)
        record = {
            "episodes": config.pretrain_episodes,
            "samples": len(demos.actions),
            "scripted_success_rate": demos.success_rate,
            **fit,
            "seconds": round(time.perf_counter() - pretrain_start, 2),
        }
        atomic_write_text(out / "pretrain.json", json.dumps(record, indent=2))

    if config.pretrain_episodes and isinstance(venv, VecNormalize):
        # The clone was fitted to observations scaled by the demonstrations' statistics; left
        # to follow PPO's rollouts they drift, and the unchanged network then plays worse
        # (Score from rest: a clone at 86 % fell to 6-30 % with the learning rate at 1e-12).
        venv.training = False

    stop = StopOnSignal()
    checkpoint = CheckpointCallback(out, config.checkpoint_freq)
    own: list[BaseCallback] = [stop, checkpoint]
    if config.self_play:
        own.append(
            SelfPlayCallback(
                window=config.selfplay_window,
                threshold=config.selfplay_threshold,
                rule=config.selfplay_rule,
                pool_size=config.selfplay_pool,
                save_dir=out / "selfplay",
                verbose=1,
                sampled=config.selfplay_sampled,
                gate=(
                    ReplacementGate(config.env_id, config.env_kwargs, config.selfplay_gate)
                    if config.selfplay_gate
                    else None
                ),
            )
        )
    if config.teacher_steps:
        own.append(
            TeacherCallback(
                config.env_id,
                config.env_kwargs,
                config.teacher_steps,
                seed=config.seed,
                teacher=config.teacher,
            )
        )
    curve = EvalCurveCallback(config, out, wall_offset)
    own.append(curve)
    if config.video_every is not None:
        own.append(VideoCallback(config, out, curve))

    start = time.perf_counter()
    remaining = max(config.timesteps - done_steps, 0)
    try:
        if remaining:
            with stop.installed():
                model.learn(
                    remaining,
                    callback=CallbackList(own + list(callbacks or [])),
                    progress_bar=progress_bar,
                    reset_num_timesteps=not continuing,
                    tb_log_name="run",
                )
        if stop.signum is not None:
            checkpoint.num_timesteps = model.num_timesteps
            checkpoint.write()
            return TrainResult(
                out, int(model.num_timesteps), time.perf_counter() - start, None, stop.signum
            )
        rows = read_curve(out / "eval.csv") if (out / "eval.csv").exists() else []
        if curve.reached is None and (not rows or rows[-1]["timesteps"] < model.num_timesteps):
            curve.init_callback(model)  # a last point for the curve at the final timestep
            curve.run_eval()
        save_model(model, out / MODEL_FILE, out / NORM_FILE)
    finally:
        venv.close()
    return TrainResult(out, int(model.num_timesteps), time.perf_counter() - start, curve.reached)


def _load_checkpoint(config: TrainConfig, out: Path, venv: Any) -> tuple[Any, int]:
    """The model of the run's last checkpoint (or its final model), and its timesteps.

    The model is built from the run's configuration and given the checkpoint's weights and
    optimiser state, read as tensors, so nothing is unpickled. A checkpoint of a run from
    before (with ``vecnormalize.pkl``) is refused, with how to migrate it.
    """
    pointer_file = out / CHECKPOINT_DIR / LATEST_FILE
    if pointer_file.exists():
        pointer = json.loads(pointer_file.read_text())
        zip_path = out / CHECKPOINT_DIR / pointer["model"]
        norm_path = (
            out / CHECKPOINT_DIR / pointer["vecnormalize"] if "vecnormalize" in pointer else None
        )
    else:
        zip_path, pointer = out / MODEL_FILE, None
        found = [out / n for n in (NORM_FILE, LEGACY_NORM_FILE) if (out / n).exists()]
        norm_path = found[0] if found else None
    if norm_path is not None and isinstance(venv, VecNormalize):
        read_norm(norm_path, out, trust=False).apply(venv)
    try:
        data, params, variables = read_model_zip(zip_path)
    except ValueError as err:
        raise ValueError(f"cannot resume from {zip_path}: {err}") from None
    model = build_model(config, venv, out / "tb")
    try:
        model.set_parameters(params, exact_match=True, device="cpu")
    except (ValueError, RuntimeError) as err:
        raise ValueError(f"{zip_path} does not fit the run's configuration: {err}") from None
    for name, value in (variables or {}).items():
        if value is not None:
            getattr(model, name).data = value.data
    steps = int(pointer["timesteps"]) if pointer else int(data.get("num_timesteps", 0))
    model.num_timesteps = steps
    model._n_updates = int(data.get("_n_updates", 0))
    return model, steps
