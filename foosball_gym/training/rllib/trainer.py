"""The RLlib backend's training loop: :func:`train_rllib` starts or resumes a run.

See :mod:`foosball_gym.training.rllib` for what it trains and the files it writes.
"""

from __future__ import annotations

import functools
import json
import shutil
import time
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from foosball_gym.evaluation import evaluate
from foosball_gym.training.config import TrainConfig
from foosball_gym.training.loading.rllib_policy import actor_layers, load_rllib_policy
from foosball_gym.training.resume import set_aside_after
from foosball_gym.training.rllib.env_runner import (
    ENV_NAME,
    LEARNER,
    make_game,
    map_agent,
    opponent_id,
)
from foosball_gym.training.rllib.export import export_policy
from foosball_gym.training.rllib.opponent_pool import OpponentPool
from foosball_gym.training.rllib.ray_config import build_config, check_rllib_config
from foosball_gym.training.rllib.ray_start import require_ray, start_ray
from foosball_gym.training.rllib.tensorboard_writer import TensorboardWriter
from foosball_gym.training.run_dir.best import BestModel
from foosball_gym.training.run_dir.curve import EVAL_SEED, EvalCurve, eval_row
from foosball_gym.training.run_dir.files import (
    CHECKPOINT_DIR,
    CONFIG_FILE,
    LATEST_FILE,
    POLICY_FILE,
    POLICY_INFO_FILE,
    RLLIB_BACKEND,
    SELFPLAY_DIR,
    TB_DIR,
    atomic_write_text,
    clear_stale,
    has_checkpoint,
    read_backend,
    read_latest,
    write_latest,
)
from foosball_gym.training.run_dir.lock import run_lock
from foosball_gym.training.run_dir.physics import (
    PhysicsMismatchWarning,
    physics_mismatch,
    physics_record,
)
from foosball_gym.training.run_dir.tensors import load_tensors, save_tensors
from foosball_gym.training.signals import Interrupted, SignalStop

BACKEND = RLLIB_BACKEND


@dataclass
class RllibTrainResult:
    """What a call of :func:`train_rllib` did (the fields of the SB3 backend's TrainResult).

    ``signal`` is the signal (SIGINT, SIGTERM) that stopped the run before its budget, after a
    checkpoint was written; None where it ran to the end.
    """

    out: Path
    timesteps: int
    seconds: float
    reached: dict[str, float] | None
    signal: int | None = None
    generation: int = 0
    games: int = 0


def train_rllib(
    config: TrainConfig,
    out: str | Path,
    *,
    num_workers: int = 2,
    address: str | None = None,
    resume: bool = False,
    verbose: int = 1,
) -> RllibTrainResult:
    """Train (or, with ``resume``, continue) self-play PPO on Ray RLlib in run directory ``out``.

    The configuration is the SB3 backend's: ``n_steps * n_envs`` env steps per update, spread
    over the env runners (``n_envs // num_workers`` envs each, at least one), minibatches of
    ``batch_size``, ``n_epochs`` passes, ``net_arch`` for both actor and critic (tanh).
    Checkpoints every ``checkpoint_freq`` steps, an evaluation every ``eval_freq`` steps,
    both checked after each RLlib iteration (one update).

    Args:
        config: the run's configuration (ignored with ``resume``: the run's own is read).
        out: the run directory.
        num_workers: Ray env runners sampling in parallel, one CPU each; 0 samples in this
            process.
        address: the Ray cluster: ``HOST:PORT`` of its head, ``"auto"`` (the one this machine
            belongs to), or None to start a local Ray with ``max(num_workers, 1)`` CPUs. An
            already initialised Ray is used as it is.
        resume: continue from the last checkpoint in ``out``.
        verbose: 1 prints each replacement of the opponent.

    Raises:
        ImportError: Ray RLlib is missing (the message names the extra).
        ValueError: the configuration cannot be trained here, or ``out`` holds a run already
            (without ``resume``) or another backend's run.
    """
    require_ray()
    import torch as th

    out = Path(out)
    if resume:
        if read_backend(out) != BACKEND:
            raise ValueError(f"{out} is a run of the {read_backend(out)} backend, not rllib's")
        config = TrainConfig.load(out / CONFIG_FILE)
        mismatch = physics_mismatch(json.loads((out / CONFIG_FILE).read_text()), f"the run {out}")
        if mismatch:
            warnings.warn(
                f"{mismatch} Resuming continues it on the current physics.",
                PhysicsMismatchWarning,
                stacklevel=2,
            )
    check_rllib_config(config, num_workers)
    # Recorded as run: RLlib scales neither observations nor rewards here, and its Adam and its
    # update are its own (PyTorch).
    config.normalize = config.normalize_reward = False
    config.adam_eps, config.fused_adam, config.learner = None, False, "torch"
    if out.exists() and not out.is_dir():
        raise ValueError(f"{out} is a file, not a run directory")
    th.set_num_threads(config.torch_threads)
    # Everything written into the run from here is written by this training alone.
    with run_lock(out):
        continuing = resume and has_checkpoint(out)
        if not resume and has_checkpoint(out):
            raise ValueError(
                f"{out} already holds a run; use --resume to continue it or choose another --out"
            )
        return _train(config, out, continuing, num_workers, address, verbose)


def _train(
    config: TrainConfig,
    out: Path,
    continuing: bool,
    num_workers: int,
    address: str | None,
    verbose: int,
) -> RllibTrainResult:
    import ray
    from ray.tune.registry import register_env

    selfplay = OpponentPool(config, out / SELFPLAY_DIR)
    curve = EvalCurve(out, config.env_id)
    done_steps, wall_offset = 0, 0.0
    pointer: dict[str, Any] | None = None
    restored: dict[str, Any] = {}
    if continuing:
        pointer = read_latest(out)
        if pointer is None or "checkpoint" not in pointer:
            raise ValueError(f"{out / CHECKPOINT_DIR / LATEST_FILE} names no rllib checkpoint")
        done_steps = int(pointer["timesteps"])
        set_aside_after(out, done_steps, config.env_id)
        restored = selfplay.restore()
        wall_offset = curve.wall_seconds()
    else:
        clear_stale(out)
    best = BestModel(out)  # after the stale best/ of a failed start is gone
    remaining = max(config.timesteps - done_steps, 0)
    lr_start = config.learning_rate
    if config.lr_schedule == "linear":
        lr_start *= remaining / config.timesteps

    started = start_ray(address, num_workers)
    algo = None
    board = TensorboardWriter(out / TB_DIR / BACKEND)
    try:
        register_env(ENV_NAME, make_game)
        opponents = selfplay.module_ids if continuing else (opponent_id(0),)
        algo = build_config(config, num_workers, opponents, lr_start, remaining).build_algo()
        if continuing:
            assert pointer is not None  # read above when continuing
            step_dir = out / CHECKPOINT_DIR / pointer["checkpoint"]
            _set_modules(algo, {LEARNER: load_tensors(step_dir / "learner.pt"), **restored})
            optimizer = step_dir / "optimizer.pt"
            if optimizer.exists():
                algo.learner_group.set_state({"learner": load_tensors(optimizer)})
        else:
            state = _learner_state(algo)
            if config.log_std_init:
                head = actor_layers(state)[-1][1]  # the bias: means, then log std
                head[head.shape[0] // 2 :] = config.log_std_init
                _set_modules(algo, {LEARNER: state})
            selfplay.add(state, 0, None, 0.0)
            _set_modules(algo, {opponent_id(0): state})
            _save_config(config, num_workers, out / CONFIG_FILE)

        stop = SignalStop()
        steps = done_steps
        start = time.perf_counter()
        next_eval = (steps // config.eval_freq + 1) * config.eval_freq
        next_checkpoint = (steps // config.checkpoint_freq + 1) * config.checkpoint_freq
        reached = None
        last_eval = done_steps if continuing else -1

        def export(directory: Path, state: Mapping[str, Any]) -> None:
            export_policy(
                state,
                directory,
                env_id=config.env_id,
                env_kwargs=config.env_kwargs,
                timesteps=steps,
                generation=selfplay.generation,
            )

        def checkpoint() -> None:
            name = f"step_{steps:010d}"
            step_dir = out / CHECKPOINT_DIR / name
            step_dir.mkdir(parents=True, exist_ok=True)
            state = _learner_state(algo)
            save_tensors(state, step_dir / "learner.pt")
            save_tensors(
                algo.learner_group.get_state(components="learner/optimizer")["learner"],
                step_dir / "optimizer.pt",
            )
            export(step_dir, state)
            write_latest(out, {"checkpoint": name, "timesteps": steps, "backend": BACKEND})

        def run_eval() -> dict[str, Any] | None:
            nonlocal last_eval
            # Evaluated as exported, so the curve measures the policy `foosball eval` loads.
            candidate = best.dir / "candidate"
            export(candidate, _learner_state(algo))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", PhysicsMismatchWarning)
                policy = load_rllib_policy(candidate)
            try:
                with stop.interruptible():
                    res = evaluate(
                        policy,
                        config.env_id,
                        config.env_kwargs,
                        episodes=config.eval_episodes,
                        seed=EVAL_SEED,
                    )
            except Interrupted:
                shutil.rmtree(candidate, ignore_errors=True)
                return None
            row = eval_row(res, steps, wall_offset + time.perf_counter() - start)
            curve.append(row)
            board.scalars(
                {"eval/success_rate": row["success_rate"], "eval/mean_reward": row["mean_reward"]},
                steps,
            )

            def keep(best_dir: Path) -> None:
                for name in (POLICY_FILE, POLICY_INFO_FILE):
                    (candidate / name).replace(best_dir / name)

            best.offer(row, keep)
            shutil.rmtree(candidate, ignore_errors=True)
            last_eval = steps
            return row

        with stop.installed():
            rows = curve.rows()
            if continuing and (steps // config.eval_freq) * config.eval_freq > (
                rows[-1]["timesteps"] if rows else 0
            ):
                # Due before the checkpoint this run goes on from, and never written (a signal
                # stopped it half-way): the policy is the checkpoint's still.
                run_eval()
            while steps < config.timesteps and stop.signum is None:
                result = algo.train()
                runners = result.get("env_runners", {})
                steps = done_steps + int(result.get("num_env_steps_sampled_lifetime", 0))
                games = runners.get("selfplay_games")
                games = [] if games is None or np.isscalar(games) else list(games)
                replaced = selfplay.judge(games)
                for line in selfplay.take_stalls(steps):
                    print(line, flush=True)  # whatever the verbosity: see SelfPlayCallback
                if replaced is not None:
                    score, elo = replaced
                    state = _learner_state(algo)
                    generation = selfplay.add(state, steps, score, elo)
                    new_id = opponent_id(generation)
                    _add_opponent(algo, new_id, selfplay.module_ids)
                    _set_modules(algo, {new_id: state})
                    if verbose:
                        print(
                            f"self-play: opponent replaced by generation {generation} at "
                            f"{steps} steps ({config.selfplay_rule} {score:+.2f}, "
                            f"Elo {elo:+.0f})"
                        )
                learner_stats = result.get("learners", {}).get(LEARNER, {})
                board.scalars(
                    {
                        "rollout/ep_len_mean": runners.get("episode_len_mean"),
                        "train/policy_loss": learner_stats.get("policy_loss"),
                        "train/value_loss": learner_stats.get("vf_loss"),
                        "train/entropy": learner_stats.get("entropy"),
                        **selfplay.rates(),
                    },
                    steps,
                )
                if steps >= next_checkpoint:
                    next_checkpoint = (steps // config.checkpoint_freq + 1) * config.checkpoint_freq
                    checkpoint()
                if steps >= next_eval:
                    next_eval = (steps // config.eval_freq + 1) * config.eval_freq
                    row = run_eval()
                    target = config.target_success
                    if row is None:  # a signal ended the evaluation
                        break
                    if target is not None and row["success_rate"] >= target:
                        reached = row
                        break
        seconds = time.perf_counter() - start
        checkpoint()
        if stop.signum is not None:
            return RllibTrainResult(
                out, steps, seconds, None, stop.signum, selfplay.generation, selfplay.games
            )
        if reached is None and last_eval < steps:
            run_eval()  # a last point for the curve at the final timestep
        export(out, _learner_state(algo))
    finally:
        board.close()
        if algo is not None:
            algo.stop()
        if started:
            ray.shutdown()
    return RllibTrainResult(out, steps, seconds, reached, None, selfplay.generation, selfplay.games)


def _learner_state(algo: Any) -> dict[str, Any]:
    """The learner module's full state (actor and critic) as numpy arrays."""
    weights = algo.learner_group.get_weights(module_ids=[LEARNER])[LEARNER]
    return {k: np.asarray(v) for k, v in weights.items()}


def _set_modules(algo: Any, states: Mapping[str, Any]) -> None:
    """Give modules (learner, opponents) these weights, on the learner and every env runner."""
    algo.set_state({"learner_group": {"learner": {"rl_module": dict(states)}}})


def _add_opponent(algo: Any, module_id: str, pool: tuple[str, ...]) -> None:
    """Add ``module_id`` to the learner and every env runner, draw away from ``pool`` from now
    on, and remove the modules that left the pool."""
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    mapping = functools.partial(map_agent, opponents=pool)
    algo.add_module(
        module_id=module_id,
        module_spec=RLModuleSpec.from_module(algo.get_module(LEARNER)),
        new_agent_to_module_mapping_fn=mapping,
        new_should_module_be_updated=[LEARNER],
    )
    present = set(algo.config.policies) - {LEARNER}
    for old in sorted(present - set(pool)):
        algo.remove_module(
            module_id=old,
            new_agent_to_module_mapping_fn=mapping,
            new_should_module_be_updated=[LEARNER],
        )


def _save_config(config: TrainConfig, num_workers: int, path: Path) -> None:
    data = {
        **asdict(config),
        "normalize": False,
        "backend": BACKEND,
        "num_workers": num_workers,
        "physics": physics_record(),
    }
    atomic_write_text(path, json.dumps(data, indent=2))
