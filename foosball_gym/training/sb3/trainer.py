"""A Stable-Baselines3 training run: :func:`train` starts, resumes or lengthens one.

Its configuration is :class:`~foosball_gym.training.config.TrainConfig`; the files it writes
are listed in :mod:`foosball_gym.training.run_dir.files`.
"""

from __future__ import annotations

import contextlib
import json
import threading
import time
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch as th
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.vec_env import VecNormalize

from foosball_gym.table import PHYSICS_REVISION
from foosball_gym.training.config import TrainConfig, stall_fallback
from foosball_gym.training.resume import set_aside_after
from foosball_gym.training.run_dir.curve import EvalCurve
from foosball_gym.training.run_dir.files import (
    CONFIG_FILE,
    MODEL_FILE,
    SELFPLAY_DIR,
    TB_DIR,
    atomic_write_text,
    clear_stale,
    has_checkpoint,
)
from foosball_gym.training.run_dir.lock import run_lock
from foosball_gym.training.run_dir.physics import PhysicsMismatchWarning, physics_mismatch
from foosball_gym.training.run_dir.storage import save_model
from foosball_gym.training.sb3.callbacks import (
    CheckpointCallback,
    EvalCurveCallback,
    ProgressCallback,
    StopOnSignal,
    rollout_steps,
    steps_run,
)
from foosball_gym.training.sb3.curriculum import ServeCurriculum
from foosball_gym.training.sb3.model import build_model, load_checkpoint
from foosball_gym.training.sb3.pretrain import pretrain
from foosball_gym.training.sb3.replay import restore_run_replay
from foosball_gym.training.sb3.teacher import TeacherCallback
from foosball_gym.training.sb3.vec_env import make_env
from foosball_gym.training.sb3.videos import VideoCallback
from foosball_gym.training.selfplay.callback import SelfPlayCallback
from foosball_gym.training.selfplay.gate import ReplacementGate
from foosball_gym.training.selfplay.ladder_curriculum import LadderCurriculum

# As their authors write them (the model of learner: jax is a PPO of its own class).
ALGO_NAMES = {"ppo": "PPO", "sac": "SAC", "crossq": "CrossQ"}


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
            "resume it as it is, or train a new run (with --lr-schedule constant, a run can be "
            "extended)"
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
    written (during an evaluation, where it lands: the resumed run makes the evaluation
    first); the result's ``signal`` says which arrived.

    The run's lock (:mod:`~foosball_gym.training.run_dir.lock`) is held throughout: a second
    training into ``out`` meanwhile is refused. A resume sets aside, into ``lost/``, what the
    run recorded after the checkpoint it goes on from (:mod:`~foosball_gym.training.resume`).

    Args:
        config: the run's configuration (ignored with ``resume``: the run's own is read).
        out: the run directory.
        progress_bar: show the steps on standard error, with the last evaluation's success:
            a bar on a terminal, a line now and then elsewhere.
        resume: continue from the last checkpoint in ``out`` (or its final model).
        callbacks: extra SB3 callbacks, run after the run's own.
        timesteps: with ``resume``, train on to this many steps in all, past the run's own
            ``timesteps`` (written into its ``config.json``), so that a long run can go on
            over several sittings.

    Raises:
        ValueError: the configuration, or a file of the run, is refused (the message says
            which and why), or another training holds the run
            (:class:`~foosball_gym.training.run_dir.lock.RunInUseError`).
        OSError: the run's storage failed (full, read-only); the error names the file, and
            no temporary file is left.
    """
    out = Path(out)
    if timesteps is not None and not resume:
        raise ValueError("timesteps extends a resumed run; a new run takes config.timesteps")
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} is a file, not a run directory")
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
    try:
        config.check()
    except (ValueError, TypeError) as err:
        if not resume:
            raise
        # A value the run's own file holds: say which file.
        kind = ValueError if isinstance(err, ValueError) else TypeError
        raise kind(f"{out / CONFIG_FILE}: {err}") from None
    th.set_num_threads(config.torch_threads)
    # Everything written into the run from here is written by this training alone.
    with run_lock(out):
        continuing = resume and has_checkpoint(out)
        if not resume and has_checkpoint(out):
            raise ValueError(
                f"{out} already holds a run; use --resume to continue it or choose another --out"
            )
        return _train(config, out, continuing, progress_bar, callbacks, timesteps is not None)


def _quiet_tensorboard_writer_failures(args: Any) -> None:
    # TensorBoard's writer thread stores a failed write (a full disk) and raises it in the
    # training thread at the next write, which the command reports in one line; the thread's
    # own traceback would only repeat it, after that line.
    if isinstance(args.exc_value, OSError) and type(args.thread).__name__ == "_AsyncWriterThread":
        return
    _previous_excepthook(args)


_previous_excepthook = threading.excepthook
threading.excepthook = _quiet_tensorboard_writer_failures


def _close_tensorboard(model: Any, tb_dir: Path) -> None:
    """Close the run's TensorBoard writer after a storage failure, and remove the event files
    it left empty (a full disk leaves them at 0 bytes) with the folders they leave empty."""
    for output in getattr(getattr(model, "_logger", None), "output_formats", []):
        with contextlib.suppress(OSError):
            output.close()
    if not tb_dir.is_dir():
        return
    for events in tb_dir.glob("*/events.out.tfevents.*"):
        with contextlib.suppress(OSError):
            if events.stat().st_size == 0:
                events.unlink()
    for folder in tb_dir.iterdir():
        with contextlib.suppress(OSError):
            folder.rmdir()  # only where nothing is left in it


def _train(
    config: TrainConfig,
    out: Path,
    continuing: bool,
    progress_bar: bool,
    callbacks: list[BaseCallback] | None,
    extended: bool,
) -> TrainResult:
    venv = make_env(config)
    done_steps, wall_offset, restored = 0, 0.0, None
    try:
        if continuing:
            model, done_steps = load_checkpoint(config, out, venv)
            restored = restore_run_replay(model, out)
            set_aside_after(out, done_steps, config.env_id)
            wall_offset = EvalCurve(out, config.env_id).wall_seconds()
            if extended:
                # Only once the lengthened run is known to go on from its checkpoint.
                _record_extension(config, out)
        else:
            model = build_model(config, venv, out / TB_DIR)
            clear_stale(out)
            config.save(out / CONFIG_FILE)
    except BaseException:
        venv.close()
        raise
    if not continuing and config.pretrain_episodes:
        pretrain(model, config, out, progress_bar)

    if config.pretrain_episodes and isinstance(venv, VecNormalize):
        # The clone was fitted to observations scaled by the demonstrations' statistics; left
        # to follow PPO's rollouts they drift, and the unchanged network then plays worse
        # (Score from rest: a clone at 86 % fell to 6-30 % with the learning rate at 1e-12).
        venv.training = False

    stop = StopOnSignal()
    checkpoint = CheckpointCallback(out, config.checkpoint_freq)
    own: list[BaseCallback] = [stop, checkpoint]
    if config.self_play:
        assert config.selfplay_threshold is not None  # config.check() sets the rule's default
        own.append(
            SelfPlayCallback(
                window=config.selfplay_window,
                threshold=config.selfplay_threshold,
                rule=config.selfplay_rule,
                pool_size=config.selfplay_pool,
                save_dir=out / SELFPLAY_DIR,
                verbose=1,
                sampled=config.selfplay_sampled,
                gate=(
                    ReplacementGate(config.env_id, config.env_kwargs, config.selfplay_gate)
                    if config.selfplay_gate
                    else None
                ),
                stop=stop,
                stall_games=config.selfplay_stall_games,
                fallback=stall_fallback(config),
            )
        )
    if config.selfplay_ladder_steps:
        ladder = LadderCurriculum(
            config.selfplay_ladder_steps, len(config.selfplay_scripted_levels)
        )
        ladder.apply(venv, done_steps)  # before learn() resets the environments, as below
        own.append(ladder)
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
    if config.curriculum:
        curriculum = ServeCurriculum(config)
        # Before learn() resets the environments, so that their first episodes follow it too.
        curriculum.apply(venv, done_steps)
        own.append(curriculum)
    evaluations = EvalCurveCallback(config, out, wall_offset, stop=stop)
    own.append(evaluations)
    if config.video_every is not None:
        own.append(VideoCallback(config, out, evaluations, stop=stop))

    start = time.perf_counter()
    remaining = max(config.timesteps - done_steps, 0)
    total = steps_run(model, done_steps, remaining) if remaining else done_steps
    if continuing:
        print(f"continuing {out} from its checkpoint at step {done_steps:,}, to {total:,}")
        if restored == 0:
            print(
                "its checkpoint holds no replay buffer (written before buffers were kept): "
                f"{type(model).__name__} goes on from an empty one"
            )
        elif restored is not None:
            print(f"with the {restored:,} transitions of its replay buffer")
    # Rounding up by a rollout is worth a word where it is no small part of the run.
    if total - max(config.timesteps, done_steps) > config.timesteps // 10:
        print(
            f"training to {total:,} steps, not {config.timesteps:,}: {ALGO_NAMES[config.algo]} "
            f"collects {rollout_steps(model):,} steps at a time"
        )
    if progress_bar:
        # After the evaluations, so that the bar shows the one just made.
        own.append(ProgressCallback(total, evaluations))
    # Loading a model teacher gave PyTorch one thread, as for any policy that plays.
    th.set_num_threads(config.torch_threads)
    try:
        if remaining:
            with stop.installed():
                model.learn(
                    remaining,
                    callback=CallbackList(own + list(callbacks or [])),
                    reset_num_timesteps=not continuing,
                    tb_log_name="run",
                )
        if stop.signum is not None:
            checkpoint.num_timesteps = model.num_timesteps
            checkpoint.write()
            return TrainResult(
                out, int(model.num_timesteps), time.perf_counter() - start, None, stop.signum
            )
        rows = evaluations.curve.rows()
        if evaluations.reached is None and (
            not rows or rows[-1]["timesteps"] < model.num_timesteps
        ):
            evaluations.init_callback(model)  # a last point for the curve at the final timestep
            evaluations.run_eval()
        save_model(model, out / MODEL_FILE)
    except OSError:
        _close_tensorboard(model, out / TB_DIR)
        raise
    finally:
        venv.close()
    return TrainResult(
        out, int(model.num_timesteps), time.perf_counter() - start, evaluations.reached
    )
